"""Hostile values for every numeric and choice flag of every sub-command (hypothesis).

The ranges below are the documented ones (``--help``), restated here as the oracle: any value
outside them -- NaN, infinities, overflow, text, booleans, non-integers for integer flags --
must exit 2 with one line naming the flag, before any computation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ._cli import assert_refused, run_cli

FUZZ = settings(max_examples=12, deadline=None, derandomize=True, database=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


@dataclass(frozen=True)
class Flag:
    command: str  # key of _base
    flag: str
    lo: float | None
    hi: float | None
    lo_open: bool = False
    hi_open: bool = False
    integer: bool = False

    def __str__(self) -> str:
        return f"{self.command}{self.flag}"


U32 = 2**32 - 1
FLAGS = [
    Flag("gradcheck", "--tol", 0.0, 1.0, lo_open=True),
    Flag("gradcheck", "--n-points", 1, 10_000, integer=True),
    Flag("gradcheck", "--seed", 0, U32, integer=True),
    Flag("montecarlo", "--radius", 5.0, 5000.0),
    Flag("montecarlo", "--sigma", 0.0, 1e6, lo_open=True),
    Flag("montecarlo", "--n", 2, 10_000_000, integer=True),
    Flag("montecarlo", "--seed", 0, U32, integer=True),
    Flag("montecarlo", "--k", 0.0, 1e3, lo_open=True),
    Flag("montecarlo", "--annulus", 0.0, 1000.0, lo_open=True),
    Flag("montecarlo", "--batch", 1, 100_000, integer=True),
    Flag("posterior", "--radius", 0.0, 1e5, lo_open=True),
    Flag("posterior", "--annulus", 0.0, 1e5, lo_open=True),
    Flag("posterior", "--k", 0.0, 1e3, lo_open=True),
    Flag("posterior", "--sigma", 0.0, None, lo_open=True),
    Flag("posterior", "--walkers", 4, 10_000, integer=True),
    Flag("posterior", "--max-steps", 1, 10_000_000, integer=True),
    Flag("posterior", "--max-time", 0.0, 86_400.0, lo_open=True),
    Flag("posterior", "--seed", 0, U32, integer=True),
    Flag("posterior", "--center-rc", -1e5, 1e5),
    Flag("build-db", "--step-deg", 0.5, 60.0),
    Flag("build-db", "--template-size", 32, 4096, integer=True),
    Flag("los-locate", "--step-deg", 0.5, 60.0),
    Flag("los-locate", "--template-size", 32, 4096, integer=True),
    Flag("navigate", "--attitude-sigma-arcsec", 0.0, 648_000.0),
]

_SPECIAL = ["nan", "NaN", "-nan", "inf", "-inf", "Infinity", "1e400", "-1e400", "", " ", "abc", "True", "False",
            "None", "null", "0x10", "1,5", "1e", "½", "[1]", "5 px"]
#: Text Python's int()/float() would accept: in range, but not a plain number on a command line.
_LENIENT = ["١٠", "٣", "1_0", " 10", "10 ", "\t10"]


def _base(command: str, f: dict, tmp) -> list:
    return {
        "gradcheck": ["gradcheck", "--json"],
        "montecarlo": ["montecarlo", "--json"],
        "posterior": ["posterior", f["moon.png"], "--json"],
        "build-db": ["los", "build-db", f["mesh.obj"], "--out", tmp / "fuzz.npz", "--json", "--no-progress"],
        "los-locate": ["los", "locate", f["moon.png"], "--db", f["db.npz"], "--camera", f["camera.json"], "--json"],
        "navigate": ["navigate", f["moon.png"], "--camera", f["camera.json"], "--epoch", "2026-01-01T00:00:00Z",
                     "--attitude", "[0, 0, 0, 1]", "--json"],
        "locate": ["locate", f["moon.png"], "--json"],
    }[command]


def _outside(flag: Flag) -> st.SearchStrategy[str]:
    """Text of a value the flag must refuse."""
    parts = [st.sampled_from(_SPECIAL + _LENIENT)]
    if flag.lo is not None:
        below = st.floats(min_value=-1e12, max_value=flag.lo, allow_nan=False, exclude_max=not flag.lo_open)
        parts.append(below.map(repr))
        parts.append(st.integers(min_value=-(10**12), max_value=math.ceil(flag.lo) - 1).map(str))
    if flag.hi is not None:
        above = st.floats(min_value=flag.hi, max_value=1e300, allow_nan=False, exclude_min=not flag.hi_open)
        parts.append(above.map(repr))
        parts.append(st.integers(min_value=math.floor(flag.hi) + 1, max_value=10**20).map(str))
    if flag.integer:
        lo, hi = flag.lo if flag.lo is not None else -1e6, flag.hi if flag.hi is not None else 1e6
        parts.append(st.floats(min_value=lo, max_value=hi, allow_nan=False)
                     .filter(lambda x: not float(x).is_integer()).map(repr))
        parts.append(st.sampled_from(["1e3", "2.0", "10.5"]))
    return st.one_of(*parts)


@pytest.mark.parametrize("flag", FLAGS, ids=str)
def test_numeric_flag_outside_its_range_exits_2_naming_it(flag, inputs, tmp_path_factory):
    tmp = tmp_path_factory.getbasetemp()

    @FUZZ
    @given(value=_outside(flag))
    def case(value: str) -> None:
        extra = [flag.flag, value] + (["10"] if flag.flag == "--center-rc" else [])
        if value.startswith("-") and not value[1:2].isdigit():
            extra = [f"{flag.flag}={value}"] + extra[2:]  # "-inf" would be read as an option
        res = run_cli(_base(flag.command, inputs, tmp) + extra)
        assert_refused(res, 2, flag.flag, check="bad_arguments")

    case()


CHOICES = [
    ("locate", "--front-end", ("gradient", "scanline")),
    ("locate", "--model", ("circle", "ellipse")),
    ("locate", "--profile", ("auto", "sigmoid", "lunar-lambert", "albedo-field", "limb-darkened")),
    ("locate", "--solver", ()),
    ("montecarlo", "--model", ("circle", "ellipse")),
    ("montecarlo", "--solver", ()),
    ("posterior", "--noise", ("marginal", "known", "free")),
    ("build-db", "--pole-axis", ("x", "y", "z")),
    ("los-locate", "--pole-axis", ("x", "y", "z")),
    ("navigate", "--body", ("moon", "earth")),
]


@pytest.mark.parametrize(("command", "flag", "choices"), CHOICES, ids=lambda v: v if isinstance(v, str) else "")
def test_choice_flag_with_unknown_value_exits_2_naming_it(command, flag, choices, inputs, tmp_path_factory):
    from jaxlimb.fitting import SOLVERS

    allowed = set(choices) | set(SOLVERS) | {"moon", "earth", "sun"}
    tmp = tmp_path_factory.getbasetemp()

    @settings(max_examples=5, deadline=None, derandomize=True, database=None)
    @given(value=st.text(alphabet="abcdefghijklmnopqrstuvwxyz_-0123456789 ", min_size=1, max_size=12)
           .filter(lambda s: s not in allowed and not s.startswith("-")))
    def case(value: str) -> None:
        assert_refused(run_cli(_base(command, inputs, tmp) + [flag, value]), 2, flag, check="bad_arguments")

    case()


@pytest.mark.parametrize("argv", [
    ["los", "build-db", "{mesh.obj}", "--json"],  # --out missing
    ["los", "locate", "{moon.png}", "--camera", "{camera.json}", "--json"],  # neither --db nor --mesh
    ["los", "locate", "{moon.png}", "--db", "{db.npz}", "--mesh", "{mesh.obj}", "--camera", "{camera.json}", "--json"],
    ["navigate", "{moon.png}", "--camera", "{camera.json}", "--json"],  # --epoch/--attitude missing
    ["locate", "--json"],
    ["posterior", "{moon.png}", "--center-rc", "1", "--json"],
    ["gradcheck", "--no-such-flag", "--json"],
    ["no-such-command", "--json"],
    ["--json"],
])
def test_missing_or_unknown_arguments_exit_2(argv, inputs):
    res = run_cli([str(inputs[a[1:-1]]) if a.startswith("{") else a for a in argv])
    assert_refused(res, 2, check="bad_arguments")


@pytest.mark.parametrize(("argv", "names"), [
    (["montecarlo", "--fix", "foo", "--json"], "foo"),  # exited 0, ignoring the name
    (["montecarlo", "--fix", "r0,c0,radius,k,ymax,ymin", "--json"], "--fix"),
    (["montecarlo", "--model", "ellipse", "--fix", "r0,c0,a,theta,k,ymax,ymin", "--json"], "--fix"),
    (["montecarlo", "--resume", "--json"], "--resume"),
    (["posterior", "{moon.png}", "--fix", "bogus", "--json"], "--fix"),
    (["posterior", "{moon.png}", "--model", "sigmoid", "--noise", "known", "--json"], "--sigma"),
    (["posterior", "{moon.png}", "--radius", "10", "--json"], "--center-rc"),
    (["posterior", "{moon.png}", "--walkers", "5", "--center-rc", "60", "80", "--radius", "30", "--json"], "--walkers"),
    # inside [4, 10000] but below the twice-the-parameters floor --help states
    (["posterior", "{moon.png}", "--walkers", "4", "--center-rc", "60", "80", "--radius", "30", "--json"], "n_walkers"),
    (["posterior", "{moon.png}", "--center-rc", "1e5", "1e5", "--radius", "5", "--json"], "circle"),
    (["locate", "", "--json"], "IMAGE"),  # Path("") is the current directory: never a many-frame run
    (["locate", "{moon.png}", "--body", "earth", "--json"], "--camera"),
    (["locate", "{moon.png}", "--hints", "{hints.json}", "--body", "earth", "--json"], "--body"),
])
def test_argument_combinations_without_an_answer_exit_2(argv, names, inputs):
    res = run_cli([str(inputs[a[1:-1]]) if a.startswith("{") else a for a in argv])
    assert_refused(res, 2, names)


def test_complex_npy_image_is_refused(inputs, tmp_path):
    import numpy as np

    path = tmp_path / "complex.npy"
    np.save(path, np.ones((40, 40)) * (1 + 1j))
    res = run_cli(["posterior", path, "--center-rc", "20", "20", "--radius", "10", "--json"])
    assert_refused(res, 2, "complex", check="bad_image")


@pytest.mark.parametrize("flag", FLAGS, ids=str)
def test_numbers_python_would_coerce_are_refused(flag, inputs, tmp_path_factory):
    """Unicode digits, underscores, blanks: int()/float() take them, a command line must not."""
    for value in _LENIENT:
        extra = [flag.flag, value] + (["10"] if flag.flag == "--center-rc" else [])
        res = run_cli(_base(flag.command, inputs, tmp_path_factory.getbasetemp()) + extra)
        assert_refused(res, 2, flag.flag, check="bad_arguments")
