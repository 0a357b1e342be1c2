"""A user's own env, as a newcomer brings it: a 10-cell corridor in a module of theirs (one-hot
observations, left or right, the expert always goes right), recorded with ``abco data record``
and trained with the default settings. Every IDM method learns it; none is stopped on the way
(an IDM that fits the policy's own one-action runs is reported, not ended)."""

from __future__ import annotations

import json
import textwrap

import pytest

from abco_data.cli import main as data_main
from abco_train.cli import main as abco_main

MODULE = textwrap.dedent('''
    import gymnasium as gym
    import numpy as np
    from gymnasium import spaces

    CELLS = 10


    class Corridor(gym.Env):
        """Walk right to the last cell: reward 1 there, -0.1 a step before."""

        observation_space = spaces.Box(0.0, 1.0, (CELLS,), np.float32)
        action_space = spaces.Discrete(2)  # left, right

        def reset(self, *, seed=None, options=None):
            super().reset(seed=seed)
            self.pos = int(self.np_random.integers(0, CELLS - 1))
            return np.eye(CELLS, dtype=np.float32)[self.pos], {}

        def step(self, action):
            self.pos = min(max(self.pos + (1 if int(action) == 1 else -1), 0), CELLS - 1)
            done = self.pos == CELLS - 1
            return np.eye(CELLS, dtype=np.float32)[self.pos], 1.0 if done else -0.1, done, \\
                False, {}


    def right(obs):
        return 1


    if "Corridor10-v0" not in gym.registry:
        gym.register("Corridor10-v0", entry_point=Corridor, max_episode_steps=50)
''')
ENV = "corridor_user:Corridor10-v0"


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The module on the path and its two datasets recorded by ``abco data record``."""
    root = tmp_path_factory.mktemp("corridor")
    (root / "corridor_user.py").write_text(MODULE)
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(str(root))
        patch.setenv("ABCO_DATA_HOME", str(root / "home"))
        assert data_main(["record", "--env", ENV, "--policy", "corridor_user:right", "--kind",
                          "expert", "--episodes", "20", "--seed", "0", "--id",
                          "local/corridor10-expert-v0", "--quiet"]) == 0  # fmt: skip
        assert data_main(["record", "--env", ENV, "--kind", "pre", "--transitions", "3000",
                          "--seed", "1", "--id", "local/corridor10-pre-v0", "--quiet"]) == 0
        yield root


@pytest.mark.parametrize("method", ["abco", "bco", "bco-alpha", "bco-alpha-torabi", "iupe"])
def test_every_idm_method_learns_the_corridor_with_its_defaults(recorded, tmp_path, method,
                                                                monkeypatch):  # fmt: skip
    monkeypatch.syspath_prepend(str(recorded))
    monkeypatch.setenv("ABCO_DATA_HOME", str(recorded / "home"))
    run_dir = tmp_path / method
    assert abco_main(["train", "--env", ENV, "--method", method, "--expert-data",
                      "local/corridor10-expert-v0", "--pre-data", "local/corridor10-pre-v0",
                      "--run-dir", str(run_dir), "--quiet", "--no-plots"]) == 0  # fmt: skip
    final = json.loads((run_dir / "final.json").read_text())
    assert final["status"] == "ok" and final["episodes"]["score"] >= 0.95, final["episodes"]


@pytest.mark.parametrize("method, steps", [("dilo", ["--dilo-steps", "40"]),
                                           ("lapo", ["--lapo-schedule", "steps",
                                                     "--lapo-model-steps", "40",
                                                     "--lapo-policy-steps", "40"])])
def test_the_offline_methods_run_on_the_recorded_corridor(recorded, tmp_path, method, steps,
                                                          monkeypatch):  # fmt: skip
    """DILO and LAPO end to end on a user's recorded env (few steps: that they run, count
    the user's pre-demonstrations and score; their defaults' scores are measured elsewhere)."""
    monkeypatch.syspath_prepend(str(recorded))
    monkeypatch.setenv("ABCO_DATA_HOME", str(recorded / "home"))
    run_dir = tmp_path / method
    assert abco_main(["train", "--env", ENV, "--method", method, "--expert-data",
                      "local/corridor10-expert-v0", "--pre-data", "local/corridor10-pre-v0",
                      "--run-dir", str(run_dir), "--quiet", "--no-plots", *steps]) == 0
    final = json.loads((run_dir / "final.json").read_text())
    assert final["status"] == "ok" and -1.5 < final["episodes"]["score"] <= 1.5
    assert final["interactions"]["pre_demonstration"] == 3000
