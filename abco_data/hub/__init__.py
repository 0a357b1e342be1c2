"""Getting and publishing datasets: the local cache, the Hugging Face Hub, then local
generation (:mod:`~abco_data.hub.fetch`), the Hub calls with their time limits
(:mod:`~abco_data.hub.calls`), the manifest that pins each dataset's bytes
(:mod:`~abco_data.hub.manifest`), one fetch of a dataset at a time
(:mod:`~abco_data.hub.fetch_lock`) and publishing (:mod:`~abco_data.hub.publish`)."""
