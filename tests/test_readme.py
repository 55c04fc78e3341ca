"""The README stays true: its first lines, its Python examples, its command table and its numbers."""

import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
RESULTS = ROOT / "benchmarks" / "results"


def _text() -> str:
    return README.read_text()


def test_first_lines_give_the_two_commands():
    head = _text().splitlines()[:6]
    assert any(line.startswith("make demo") for line in head)
    assert any(line.startswith("make test") for line in head)


def test_readme_is_short():
    assert len(_text().splitlines()) <= 300


def test_quick_start_example_runs():
    block = re.search(r"## Quick start \(Python\)\n\n```python\n(.*?)```", _text(), re.S)
    assert block, "README lost its quick-start example"
    ns: dict = {}
    exec(compile(block.group(1), "README.md", "exec"), ns)  # noqa: S102 - our own README
    res = ns["res"]
    assert bool(res.converged)
    assert abs(float(res.params.r0) - 200.3) < 5 * float(res.std["r0"])


def test_locate_example_runs():
    import math

    block = re.search(r"## Locate a body \(Python\)\n\n```python\n(.*?)```", _text(), re.S)
    assert block, "README lost its locate example"
    ns: dict = {}
    exec(compile(block.group(1), "README.md", "exec"), ns)  # noqa: S102 - our own README
    m, truth = ns["m"], ns["truth"]
    assert math.dist(m.center_rc, truth.center_rc) < 0.05
    assert abs(m.radius_px - truth.apparent_radius_px) < 0.05
    assert m.extras["profile"]["model"] == "lunar-lambert"


def test_command_table_names_every_subcommand():
    from jaxlimb.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    table = re.search(r"\| command \| what it does \|\n(.*?)\n\n", _text(), re.S).group(1)
    for name, p in sub.choices.items():
        nested = [a for a in p._actions if hasattr(a, "choices") and isinstance(a.choices, dict)]
        names = [f"jaxlimb {name} {n}" for a in nested for n in a.choices] or [f"jaxlimb {name}"]
        for full in names:
            assert f"`{full}" in table, f"README's command table misses `{full}`"
    assert "--kernels" in re.search(r"`jaxlimb navigate[^|]*\|[^\n]*", table).group(0)


def test_links_point_to_files():
    for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", _text()):
        assert (ROOT / target).exists(), f"README links to a missing file: {target}"


def _load(name: str) -> dict:
    return json.loads((RESULTS / name).read_text())


def _families_all(name: str, body: str) -> dict:
    return _load(name)["summary"][body]["all"]


def test_summary_numbers_are_the_results_files():
    """Every number of the README's accuracy/speed table is the one in benchmarks/results/ (rounded)."""
    acc = _load("locate_accuracy.json")["summary"]["gibbous"]
    moon, earth = _families_all("families_moon.json", "moon"), _families_all("families_earth.json", "earth")
    irregular = re.search(r"Attitude unknown, Sun known: by phase.*?\| all \| \d+ \| \d+ \| ([\d.]+) / ([\d.]+) /",
                          _load("irregular_los.json")["report"], re.S)
    hmi = _load("sun_limb.json")["results"][0]
    mc = _load("montecarlo_circle.json")["rms_over_crlb"].values()
    lm = next(r for r in _load("solvers.json")["rows"] if r["scenario"] == "nominal" and r["solver"] == "lm")
    cli = _load("cli_speed.json")
    expected = [
        f"**{acc['phys_center_p90']:.3f} px** with the physical profile, {acc['center_p90']:.3f} px with the papers' sigmoid",
        f"centre error median {moon['center_median_px']:.3f} px, p90 {moon['center_p90_px']:.3f} px; "
        f"{moon['n_ok']} of {moon['n']} frames answered, {moon['n'] - moon['n_ok']} typed refusal"
        f"{'' if moon['n'] - moon['n_ok'] == 1 else 's'}; mean NEES {moon['nees_mean']:.1f}",
        f"centre error median {earth['center_median_px']:.3f} px, p90 {earth['center_p90_px']:.3f} px; "
        f"{earth['n_ok']} of {earth['n']} answered",
        f"centre error median {irregular.group(1)} px, p90 {irregular.group(2)} px",
        f"{hmi['limb_darkened']['radius_err_px']:+.3f} px with the limb-darkened disc, "
        + f"{hmi['sigmoid']['radius_err_px']:.3f} px with the sigmoid".replace("-", "−"),
        f"{min(mc):.3f}–{max(mc):.3f} over the six parameters",
        f"{lm['ms_per_fit_median']:.2f} ms per fit, {lm['speedup_vs_scipy_numpy_single']:.1f}× SciPy",
        f"{cli['median_s']['locate_moon']:.2f} s, {cli['ratio_to_jax_start']['locate_moon']:.2f}× a bare `import jax`",
        f"{_load('dask_montecarlo.json')['speedup_2_vs_1']:.2f}× one worker",
    ]
    text = _text()
    for line in expected:
        assert line in text, f"README's summary does not say what benchmarks/results/ says: {line!r}"
