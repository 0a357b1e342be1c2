"""Datasets of the user's own: recording any Gymnasium env (:mod:`~abco_data.user.record`)
with a policy named ``MODULE:CALLABLE`` (:mod:`~abco_data.user.policies`,
:mod:`~abco_data.user.code`, run in a child process by :mod:`~abco_data.user.forked_call`),
writing them in abco's format (:mod:`~abco_data.user.writer`), their ids ``local/NAME-v0``
(:mod:`~abco_data.user.ids`), the user manifest (:mod:`~abco_data.user.datasets`) and their
command line (:mod:`~abco_data.user.cli`)."""
