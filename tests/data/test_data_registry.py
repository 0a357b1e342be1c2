"""The registry of the dataset ids: twelve of Table 1, three start-cell pre-demonstrations,
four procedural ones, one held-action set (Acrobot), LunarLander's two, then the four
classic-control expert datasets' version 1."""

import pytest

import abco_data
import abco_envs
from abco_data.errors import UnknownDatasetError
from abco_data.registry import ADDED_ENVS, ENV_NAMES, TABLE1_ENVS


def test_twelve_ids_two_kinds_per_env():
    assert len(abco_data.DATASET_IDS) == 26
    assert len(set(abco_data.DATASET_IDS)) == 26
    assert abco_data.DATASET_IDS[12:15] == tuple(f"abco/maze{n}x{n}-pre-start-v0"
                                                 for n in (3, 5, 10))
    assert abco_data.DATASET_IDS[15:19] == tuple(f"abco/maze{n}x{n}-procedural-{k}-v0"
                                                 for n in (5, 10) for k in ("expert", "pre"))
    assert abco_data.DATASET_IDS[19:20] == ("abco/acrobot-pre-held-v0",)
    assert abco_data.DATASET_IDS[20:22] == ("abco/lunarlander-expert-v0",
                                            "abco/lunarlander-pre-v0")
    assert abco_data.DATASET_IDS[22:] == tuple(f"abco/{name}-expert-v1" for name in
                                               ("cartpole", "acrobot", "mountaincar",
                                                "lunarlander"))  # fmt: skip
    for env_id in (*abco_envs.MAZE_IDS, *abco_envs.CLASSIC_IDS):
        for kind in ("expert", "pre_demonstrations"):
            s = abco_data.spec(abco_data.dataset_id(env_id, kind))
            assert (s.env_id, s.kind) == (env_id, kind)


def test_lunar_lander_datasets_are_made_as_the_classic_ones():
    """The counts of the other classic-control datasets, and seeds after every older one's
    (so no older dataset's seed, or bytes, moved when they were added)."""
    for kind in ("expert", "pre"):
        lunar = dict(abco_data.spec(f"abco/lunarlander-{kind}-v0").params)
        cartpole = dict(abco_data.spec(f"abco/cartpole-{kind}-v0").params)
        assert {**lunar, "seed": 0} == {**cartpole, "seed": 0}
    seeds = [abco_data.spec(i).params["seed"] for i in abco_data.DATASET_IDS[:22]]
    assert seeds == [(k + 1) * 1_000_000 for k in range(22)]
    assert set(ENV_NAMES) == {*TABLE1_ENVS, *ADDED_ENVS}


def test_id_spelling():
    assert abco_data.dataset_id("AbcoMaze5x5-v0", "expert") == "abco/maze5x5-expert-v0"
    assert abco_data.dataset_id("abco_envs:AbcoMaze5x5-v0", "pre") == "abco/maze5x5-pre-v0"
    assert abco_data.spec("abco/cartpole-pre-v0").filename == "cartpole-pre-v0.hdf5"


def test_seeds_are_distinct():
    seeds = [abco_data.spec(i).params["seed"] for i in abco_data.DATASET_IDS[:22]]
    assert len(set(seeds)) == 22


@pytest.mark.parametrize("name", ["cartpole", "acrobot", "mountaincar", "lunarlander"])
def test_classic_expert_v1_is_v0_with_references_over_more_episodes(name):
    """Version 1 keeps v0's seed (its episodes' bytes) and raises the reference episodes; it is
    the default of every run, and v0 stays loadable."""
    v0, v1 = (abco_data.spec(f"abco/{name}-expert-v{k}").params for k in (0, 1))
    assert {**v1, "reference_episodes": 100, "reference_expert_episodes": 20} == dict(v0)
    assert (v1["reference_episodes"], v1["reference_expert_episodes"]) == (2000, 1000)
    env_id = abco_data.spec(f"abco/{name}-expert-v1").env_id
    assert abco_data.dataset_id(env_id, "expert") == f"abco/{name}-expert-v1"
    assert abco_data.dataset_id(env_id, "pre") == f"abco/{name}-pre-v0"


def test_held_action_dataset():
    from abco_data.registry import held_dataset_id

    s = abco_data.spec("abco/acrobot-pre-held-v0")
    assert (s.env_id, s.kind) == ("Acrobot-v1", "pre_demonstrations")
    plain = abco_data.spec("abco/acrobot-pre-v0").params
    assert dict(s.params) == {**plain, "hold": 4, "seed": s.params["seed"]}
    assert "hold" not in plain  # the -pre- datasets' parameters (and bytes) stay as they were
    assert held_dataset_id("Acrobot-v1") == s.id
    assert abco_data.dataset_id("Acrobot-v1", "pre") == "abco/acrobot-pre-v0"  # not a default
    with pytest.raises(UnknownDatasetError, match="held-action"):
        held_dataset_id("CartPole-v1")


def test_unknown_id_lists_known_ones():
    with pytest.raises(UnknownDatasetError) as err:
        abco_data.spec("abco/maze7x7-expert-v0")
    assert "abco/maze7x7-expert-v0" in str(err.value)
    assert "abco/maze5x5-expert-v0" in str(err.value)
    with pytest.raises(UnknownDatasetError):
        abco_data.dataset_id("Pendulum-v1", "expert")
    with pytest.raises(ValueError):
        abco_data.dataset_id("CartPole-v1", "posterior")


def test_overrides_are_checked():
    s = abco_data.spec("abco/maze3x3-pre-v0")
    assert s.with_overrides(layouts=3).params["layouts"] == 3
    assert s.params["layouts"] == 100  # the registry's spec is untouched
    with pytest.raises(TypeError, match="episodes_per_layut"):
        s.with_overrides(episodes_per_layut=3)


def test_action_counts_are_the_envs():
    import gymnasium as gym

    import abco_envs  # noqa: F401  (registers the mazes)

    for env_id, n in abco_data.registry.ACTION_COUNTS.items():
        kwargs = {"obs_type": "image", "image_size": 32} if "Maze" in env_id else {}
        assert gym.make(env_id, **kwargs).action_space.n == n, env_id
