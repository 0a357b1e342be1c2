"""Aggregates of a grid across its environments, rliable-style, and which envs separate methods.

``abco report`` puts every method that has finished runs on all six environments of Table 1
into one score matrix of P (runs x envs) and summarises it with the ``rliable`` package
(Agarwal et al., "Deep RL at the Edge of the Statistical Precipice", NeurIPS 2021), an optional
extra (``pip install "abco[stats]"``):

* IQM and mean of P over all runs and envs (``rliable.metrics.aggregate_iqm`` /
  ``aggregate_mean``) with 95% stratified bootstrap intervals
  (``rliable.library.get_interval_estimates``: runs resampled within each env);
* performance profiles, the fraction of runs with P above tau
  (``rliable.library.create_performance_profile``, plotted by ``rliable.plot_utils``);
* the probability of improvement of every method over a baseline, P(X > Y) averaged over
  envs (``rliable.metrics.probability_of_improvement``), with stratified independent
  bootstrap intervals (the two methods may have different numbers of runs).

rliable's bootstrap needs one rectangular matrix per method: a method with unequal numbers of
finished runs across envs keeps, on every env, its ``n`` lowest-numbered seeds, ``n`` being
the fewest it has on any env (the report says how many runs that drops). Runs stopped by their
method (e.g. ``idm_at_chance``) have no P and are not in the matrix.

Without rliable (or with a broken install) the report says so and writes everything else.

Example:
    >>> x, y = np.array([[1.0, 2.0], [3.0, 4.0]]), np.array([[0.0, 2.0], [0.0, 5.0]])
    >>> probability_of_improvement(x, y)  # env 1: 4/4 pairs better; env 2: 1 + 0.5 tie of 4
    0.6875
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

__all__ = [
    "REPS", "SEED", "TAU", "SEPARATION", "PROFILE_PNG", "INSTALL_HINT", "load_rliable",
    "score_matrices", "probability_of_improvement", "seeded", "Aggregates", "compute",
    "section", "separation", "plot_profiles", "profile_taus",
]  # fmt: skip

#: Bootstrap replicates of every interval (rliable's default for performance profiles).
REPS = 2000
#: Seed of numpy's global generator during the bootstrap (rliable draws from it).
SEED = 0
#: The P of the issue's goal: the report gives each method's fraction of runs above it.
TAU = 0.95
#: Envs where every method's mean P lies within this of the others do not separate methods.
SEPARATION = 0.02
PROFILE_PNG = "performance_profile.png"
INSTALL_HINT = 'pip install "abco[stats]"'

Scores = Mapping[str, Mapping[str, Mapping[int, float]]]  # method -> env -> seed -> P


def load_rliable() -> tuple[SimpleNamespace | None, str | None]:
    """``(rliable modules, None)``, or ``(None, why not)`` when it cannot be imported."""
    try:
        from rliable import library, metrics, plot_utils
    except ModuleNotFoundError as exc:
        return None, f"rliable is not installed ({exc})"
    except Exception as exc:  # e.g. rliable's arch<8 on pandas 3: a broken install
        return None, f"rliable could not be imported ({type(exc).__name__}: {exc})"
    return SimpleNamespace(library=library, metrics=metrics, plot_utils=plot_utils), None


def score_matrices(
    scores: Scores, envs: Sequence[str]
) -> tuple[dict[str, np.ndarray], dict[str, int], dict[str, list[str]]]:
    """Per method on every env of ``envs``: its ``(runs, envs)`` matrix of P.

    Returns:
        The matrices (the ``n`` lowest seeds per env, ``n`` the fewest runs on any env), the
        runs each method's matrix dropped to be rectangular, and the methods left out with
        the envs they lack.
    """
    matrices, dropped, left_out = {}, {}, {}
    for method, by_env in scores.items():
        lacking = [e for e in envs if not by_env.get(e)]
        if lacking:
            left_out[method] = lacking
            continue
        n = min(len(by_env[e]) for e in envs)
        columns = [[by_env[e][s] for s in sorted(by_env[e])[:n]] for e in envs]
        matrices[method] = np.asarray(columns, dtype=np.float64).T
        dropped[method] = sum(len(by_env[e]) for e in envs) - n * len(envs)
    return matrices, dropped, left_out


def probability_of_improvement(x: np.ndarray, y: np.ndarray) -> float:
    """P(X > Y) per env (ties count half), averaged over envs.

    The same number as ``rliable.metrics.probability_of_improvement`` (its Mann-Whitney U over
    ``n_x * n_y``), vectorised: the bootstrap calls it thousands of times.
    """
    d = np.asarray(x, dtype=np.float64)[:, None, :] - np.asarray(y, dtype=np.float64)[None]
    return float(np.mean((d > 0) + 0.5 * (d == 0)))


@contextlib.contextmanager
def seeded(seed: int) -> Iterator[None]:
    """rliable's stratified bootstrap draws from numpy's global generator (``np.random.choice``,
    whatever ``random_state`` it is given): seed it, and restore it afterwards."""
    state = np.random.get_state()  # noqa: NPY002 (rliable's generator, not ours)
    np.random.seed(seed)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


def profile_taus(matrices: Mapping[str, np.ndarray]) -> np.ndarray:
    """The thresholds of performance profiles: 61 from below 0 (or the lowest score) to past 1
    (or the highest)."""
    everything = np.concatenate([x.ravel() for x in matrices.values()])
    lo = min(0.0, np.floor(everything.min() * 10) / 10)
    hi = max(1.0, np.ceil(everything.max() * 10) / 10) + 0.05
    return np.linspace(lo, hi, 61)


@dataclass
class Aggregates:
    """The aggregates of a grid: ``(point, low, high)`` per method."""

    matrices: dict[str, np.ndarray]
    dropped: dict[str, int]
    left_out: dict[str, list[str]]
    baseline: str
    iqm: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    mean: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    poi: dict[str, tuple[float, float, float]] = field(default_factory=dict)
    profiles: dict[str, np.ndarray] = field(default_factory=dict)
    profile_cis: dict[str, np.ndarray] = field(default_factory=dict)
    taus: np.ndarray = field(default_factory=lambda: np.zeros(0))


def compute(scores: Scores, envs: Sequence[str], baseline: str, reps: int | None = None,
            rl: SimpleNamespace | None = None) -> Aggregates:  # fmt: skip
    """IQM, mean, performance profiles and probability of improvement over ``baseline``.

    Raises:
        ImportError: rliable cannot be imported (and ``rl`` was not given).
    """
    if rl is None:
        rl, why = load_rliable()
        if rl is None:
            raise ImportError(why)
    reps = int(reps or REPS)
    matrices, dropped, left_out = score_matrices(scores, envs)
    agg = Aggregates(matrices, dropped, left_out, baseline)
    if not matrices:
        return agg
    with seeded(SEED):
        point, ci = rl.library.get_interval_estimates(
            matrices, lambda x: np.array([rl.metrics.aggregate_iqm(x),
                                          rl.metrics.aggregate_mean(x)]),
            reps=reps)  # fmt: skip
    for m in matrices:
        agg.iqm[m] = (float(point[m][0]), float(ci[m][0, 0]), float(ci[m][1, 0]))
        agg.mean[m] = (float(point[m][1]), float(ci[m][0, 1]), float(ci[m][1, 1]))
    agg.taus = profile_taus(matrices)
    with seeded(SEED):
        agg.profiles, agg.profile_cis = rl.library.create_performance_profile(
            matrices, agg.taus, reps=reps)  # fmt: skip
    if baseline in matrices:
        pairs = {m: [x, matrices[baseline]] for m, x in matrices.items() if m != baseline}
        if pairs:
            with seeded(SEED):
                _, ci = rl.library.get_interval_estimates(
                    pairs, lambda x, y: np.array([probability_of_improvement(x, y)]),
                    reps=reps)  # fmt: skip
            for m, (x, y) in pairs.items():  # the point estimate: rliable's own function
                p = float(rl.metrics.probability_of_improvement(x, y))
                agg.poi[m] = (p, float(ci[m][0, 0]), float(ci[m][1, 0]))
    return agg


def plot_profiles(profiles: Mapping[str, np.ndarray], cis: Mapping[str, np.ndarray],
                  taus: np.ndarray, rl: SimpleNamespace, labels: Mapping[str, str], path: Path,
                  metric: str, title: str, tau: float | None = None) -> Path:  # fmt: skip
    """Performance profiles (``rliable.plot_utils``) of ``metric``, one line per method with
    its bootstrap band; a dotted line at ``tau`` where given."""
    from abco_train.harness.plots import pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    name = {m: labels.get(m, m) for m in profiles}
    rl.plot_utils.plot_performance_profiles(
        {name[m]: p for m, p in profiles.items()}, taus,
        performance_profile_cis={name[m]: c for m, c in cis.items()}, ax=ax,
        xlabel=rf"{metric} ($\tau$)", ylabel=rf"fraction of runs with {metric} > $\tau$",
        labelsize="medium", ticklabelsize="small")  # fmt: skip
    if tau is not None:
        ax.axvline(tau, color="grey", ls=":", lw=1)
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title(title, fontsize=9)
    return save_figure(fig, path)


def _n_envs(agg: Aggregates) -> int:
    """Envs in the matrices (0 without any)."""
    return next(iter(agg.matrices.values())).shape[1] if agg.matrices else 0


def _fmt(x: tuple[float, float, float]) -> str:
    return f"{x[0]:.3f} [{x[1]:.3f}, {x[2]:.3f}]"


def section(scores: Scores, envs: Sequence[str], baseline: str, out: Path,
            labels: Mapping[str, str], evaluation: str = "headline", reps: int | None = None,
            ) -> tuple[list[str], list[dict[str, Any]], Path | None]:  # fmt: skip
    """The report's aggregate section: Markdown lines, CSV rows and the profile plot."""
    label = {m: labels.get(m, m) for m in scores}
    lines = [f"Each method with finished runs on all {len(envs)} environments enters as a"
             f" (runs x {len(envs)} envs) matrix of P (the tables' headline evaluation). A method"
             " with unequal runs across envs keeps its lowest-numbered n seeds on every env (n:"
             " its fewest on any env); runs stopped by their method have no P and are left out."
             f" Intervals: 95% stratified bootstrap ({int(reps or REPS):,} replicates, runs"
             " resampled within each env, numpy seed 0) by `rliable`.", ""]  # fmt: skip
    matrices, dropped, left_out = score_matrices(scores, envs)
    for m, lacking in left_out.items():
        lines.append(f"- left out: {label[m]} (no finished run on {', '.join(lacking)})")
    if not matrices:
        return lines + ["", "No method has finished runs on every environment."], [], None
    rl, why = load_rliable()
    if rl is None:
        return lines + ["", f"Not computed: {why}. `{INSTALL_HINT}` adds the IQM with"
                        " stratified bootstrap intervals, performance profiles and the"
                        " probability of improvement (the rest of the report does not need"
                        " it)."], [], None  # fmt: skip
    agg = compute(scores, envs, baseline, reps, rl)
    lines += ["", f"| Method | Runs per env | IQM of P [95% CI] | Mean of P [95% CI] |"
              f" Runs with P > {TAU} |", "|---|---|---|---|---|"]  # fmt: skip
    rows: list[dict[str, Any]] = []
    for m, x in agg.matrices.items():
        above = float((x > TAU).mean())
        runs = str(x.shape[0]) + (f" ({dropped[m]} dropped)" if dropped[m] else "")
        lines.append(f"| {label[m]} | {runs} | {_fmt(agg.iqm[m])} | {_fmt(agg.mean[m])} |"
                     f" {above:.2f} |")  # fmt: skip
        base = {"table": "aggregate", "env": f"all {len(envs)}", "method": m,
                "evaluation": evaluation, "seeds": x.shape[0], "paper": ""}  # fmt: skip
        rows.append({**base, "metric": "performance", "mean": agg.mean[m][0],
                     "ci_low": agg.mean[m][1], "ci_high": agg.mean[m][2], "iqm": agg.iqm[m][0],
                     "iqm_ci_low": agg.iqm[m][1], "iqm_ci_high": agg.iqm[m][2]})  # fmt: skip
        rows.append({**base, "metric": f"fraction_above_{TAU}", "mean": above})
        if m in agg.poi:
            p = agg.poi[m]
            rows.append({**base, "metric": f"probability_of_improvement_over_{baseline}",
                         "mean": p[0], "ci_low": p[1], "ci_high": p[2]})  # fmt: skip
    png = plot_profiles(agg.profiles, agg.profile_cis, agg.taus, rl, label, out / PROFILE_PNG,
                        "P", f"Performance profiles over {_n_envs(agg)} envs (95% stratified"
                        " bootstrap bands)", TAU)  # fmt: skip
    lines += ["", f"![Performance profiles: fraction of runs with P > tau]({png.name})", "",
              f"### Probability of improvement over {labels.get(baseline, baseline)}"
              f" (baseline `{baseline}`)", ""]  # fmt: skip
    if baseline not in agg.matrices:
        lines.append(f"Not computed: the baseline `{baseline}` has no finished runs on every"
                     " environment (`abco report --baseline METHOD` picks another).")
    elif not agg.poi:
        lines.append("No other method to compare with the baseline.")
    else:
        lines += ["P(X > Y): the probability that a run of the method beats a run of the"
                  " baseline on the same env (ties count half), averaged over envs; 0.5 = no"
                  " difference.", "",
                  f"| Method | P(method > {baseline}) [95% CI] | Runs per env (method / baseline)"
                  " |", "|---|---|---|"]  # fmt: skip
        n_base = agg.matrices[baseline].shape[0]
        for m, p in agg.poi.items():
            lines.append(f"| {label[m]} | {_fmt(p)} | {agg.matrices[m].shape[0]} / {n_base} |")
    return lines, rows, png


def separation(means: Mapping[str, Mapping[str, float]], envs: Sequence[str],
               labels: Mapping[str, str], tol: float = SEPARATION) -> list[str]:  # fmt: skip
    """Which envs separate the methods: the spread of the methods' mean P on each env.

    Args:
        means: ``env -> method -> mean P`` over seeds.
        envs: The envs, in order.
        labels: Display names of methods.
        tol: At most this spread: the env does not separate the methods (saturated).
    """
    lines = [f"An environment on which every method's mean P lies within {tol} of the others"
             " does not tell the methods apart: it is saturated.", "",
             "| Env | Methods | Lowest mean P | Highest mean P | Spread | Separates methods? |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    saturated = []
    for env in envs:
        found = {m: p for m, p in means.get(env, {}).items() if np.isfinite(p)}
        if len(found) < 2:
            continue
        lo, hi = min(found, key=found.__getitem__), max(found, key=found.__getitem__)
        spread = found[hi] - found[lo]
        if spread <= tol:
            saturated.append(env)
        verdict = f"no: all within {tol}" if spread <= tol else "yes"
        lines.append(f"| {env} | {len(found)} | {found[lo]:.3f} ({labels.get(lo, lo)}) |"
                     f" {found[hi]:.3f} ({labels.get(hi, hi)}) | {spread:.3f} | {verdict} |")
    if len(lines) == 4:
        return ["Fewer than two methods on every environment: nothing to separate."]
    lines += ["", "Saturated: " + (", ".join(saturated) if saturated else "none") + "."]
    return lines
