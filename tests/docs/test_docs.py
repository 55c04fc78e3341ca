"""The documentation site: it builds with ``mkdocs build --strict`` (every link and anchor checked), its examples
run, every name it maps an equation to exists, and its tables cite result files that exist."""

from __future__ import annotations

import importlib
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
RESULTS = ROOT / "benchmarks" / "results"


def _block(page: str, title: str) -> str:
    m = re.search(rf'```\w+ title="{re.escape(title)}"\n(.*?)```', (DOCS / page).read_text(), re.S)
    assert m, f"{page} lost its {title} example"
    return m.group(1)


def test_site_builds_strict(tmp_path):
    """``mkdocs build --strict``: no warning (missing page, broken link or anchor, a griffe docstring problem, an
    unknown results table).  The notebooks are rendered as committed (executing them is ``make docs``; the
    notebook tests run them)."""
    pytest.importorskip("mkdocs")
    env = {k: v for k, v in os.environ.items() if k != "JAXLIMB_DOCS_EXECUTED"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-6000:]
    site = tmp_path / "site"
    cli = (site / "cli" / "index.html").read_text()
    for command in ("jaxlimb locate", "jaxlimb navigate", "jaxlimb los build-db", "jaxlimb los locate",
                    "jaxlimb posterior", "jaxlimb montecarlo", "jaxlimb gradcheck", "jaxlimb figures", "--kernels"):
        assert command in cli, f"the CLI reference lacks {command}"
    assert "JAXLIMB_PROGRESS" in cli and "--quiet" in cli  # the top-level help's epilog, the progress rule
    formats = (site / "formats" / "index.html").read_text()
    for name in ("camera", "hints", "result"):  # the tables generated from the package's schemas, and the schemas
        assert f"jaxlimb/schemas/{name}.schema.json" in formats
    accuracy = (site / "validation" / "accuracy" / "index.html").read_text()
    assert "benchmarks/results/families_moon.json" in accuracy and "<table>" in accuracy
    api = (site / "api" / "fitting" / "index.html").read_text()
    for name in ("jaxlimb.fitting.fit.fit", "jaxlimb.fitting.fit_batch", "jaxlimb.fitting.NormalLM"):
        assert f'id="{name}"' in api, f"the API reference lacks {name}"
    assert ":func:" not in api
    for nb in sorted((ROOT / "notebooks").glob("*.ipynb")):
        assert (site / "notebooks" / nb.stem / "index.html").is_file(), f"notebook {nb.name} is not a page"


def test_formats_example_locates_the_rendered_moon(tmp_path, monkeypatch, capsys):
    """The cam.json and hints.json of docs/formats.md, on the frame its make_moon.py renders, through the CLI."""
    from jaxlimb._schema import validate
    from jaxlimb.cli import main

    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    exec(compile(_block("formats.md", "make_moon.py"), "formats.md", "exec"), ns)  # noqa: S102 - our own docs
    truth = ns["truth"]
    (tmp_path / "cam.json").write_text(_block("formats.md", "cam.json"))
    (tmp_path / "hints.json").write_text(_block("formats.md", "hints.json"))
    capsys.readouterr()
    code = main(["locate", "moon.png", "--camera", "cam.json", "--hints", "hints.json", "--json"])
    out = json.loads(capsys.readouterr().out)
    assert code == 0, out
    validate(out, "result", "locate --json")  # the record of jaxlimb/schemas/result.schema.json
    assert max(abs(a - b) for a, b in zip(out["center_rc"], truth.center_rc)) < 0.02
    assert abs(out["radius_px"] - truth.apparent_radius_px) < 0.02
    assert out["extras"]["profile"]["model"] == "lunar-lambert"
    assert abs(out["range_km"] - truth.range_km) / truth.range_km < 1e-3


def test_formats_examples_are_complete():
    """The complete examples carry every key the code reads."""
    from dataclasses import fields

    from jaxlimb.geometry.camera import Camera
    from jaxlimb.imaging import Hints

    cam = json.loads(_block("formats.md", "cam.json"))
    assert set(cam) == {f.name for f in fields(Camera)}
    Camera.from_dict(cam)
    keys = set(json.loads(_block("formats.md", "hints.json"))) | set(json.loads(_block("formats.md", "hints_earth.json")))
    assert keys == {f.name for f in fields(Hints)}
    text = re.sub(r"<!--\s*schema:\s*(\w+)\s*-->", lambda m: _schema_tables().render(m.group(1)),
                  (DOCS / "formats.md").read_text())
    for name in {f.name for f in fields(Hints)} | {f.name for f in fields(Camera)}:
        assert f"| `{name}` |" in text, f"formats.md does not describe `{name}`"


def _schema_tables():
    """The docs hook that renders ``<!-- schema: NAME -->`` (docs/hooks/schema_tables.py)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("jaxlimb_schema_tables", DOCS / "hooks" / "schema_tables.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _resolve(name: str) -> object:
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(name)


def test_papers_page_names_exist():
    text = (DOCS / "papers.md").read_text()
    names = sorted(set(re.findall(r"`(jaxlimb(?:\.\w+)+)`", text)))
    assert len(names) > 40
    missing = []
    for name in names:
        try:
            _resolve(name)
        except (ImportError, AttributeError):
            missing.append(name)
    assert not missing, f"docs/papers.md maps equations to names that do not exist: {missing}"
    for script in re.findall(r"`(paper_figures/\w+\.py)`", text):
        assert (ROOT / script).is_file(), script


def test_every_page_names_existing_code():
    """A module moved or renamed leaves no page pointing at its old name."""
    missing = []
    for page in sorted(DOCS.rglob("*.md")):
        for name in sorted(set(re.findall(r"`(jaxlimb(?:\.\w+)+)`", page.read_text()))):
            try:
                _resolve(name)
            except (ImportError, AttributeError):
                missing.append(f"{page.relative_to(DOCS)}: {name}")
    assert not missing, missing


def test_validation_tables_cite_existing_results():
    cited = set()
    for page in (DOCS / "validation").glob("*.md"):
        for args in re.findall(r"<!--\s*results:\s*\w+((?:\s+[^\s>]+)*)\s*-->", page.read_text()):
            cited |= {a for a in args.split() if a.endswith((".json", ".md"))}
    assert cited and all((RESULTS / c).is_file() for c in cited), sorted(c for c in cited if not (RESULTS / c).is_file())


def test_results_hold_no_before_after_copies():
    """benchmarks/results keeps the current result of each benchmark; earlier runs live in git history."""
    stale = [p.name for p in RESULTS.rglob("*") if re.search(r"_(before|after|nofloor|bare|quick)\b|_before_|_after_", p.stem)]
    assert not stale, stale


HISTORY = re.compile(r"\bsessions? \d+|\bissue #?\d+|\bwork[ -]?streams?\b|\bhelper [a-z]+\d+\b", re.I)


def test_no_development_history_in_documentation():
    files = [ROOT / "README.md", ROOT / "CHANGELOG.md", ROOT / "mkdocs.yml", *DOCS.rglob("*.md"), *DOCS.rglob("*.py"),
             *(ROOT / "benchmarks").glob("*.py"), *(ROOT / "paper_figures").glob("*"), *(ROOT / "notebooks").glob("*.ipynb"),
             *(ROOT / "jaxlimb").rglob("*.py"), *(p for p in (ROOT / "tests").rglob("*.py") if p != Path(__file__))]
    hits = [f"{p.relative_to(ROOT)}: {m.group(0)}" for p in files if p.is_file() for m in HISTORY.finditer(p.read_text())]
    assert not hits, hits
