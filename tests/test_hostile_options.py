"""Hostile option values (issue 16): every bad ``--set`` value of every built-in recipe is refused
with an OptionError of one line naming the option — never another exception, never late."""

import pathlib
import subprocess
import sys

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from kubric.pipeline.options import ALLOW_LARGE_ENV, OptionError
from kubric.pipeline.recipe import get_recipe, load_builtin

ROOT = pathlib.Path(__file__).resolve().parents[1]
RECIPES = load_builtin()
OPTIONS = sorted((name, key) for name, cls in RECIPES.items() for key in cls.options)

#: values a hostile user types: non-finite numbers, huge numbers, malformed pairs, odd text
NASTY = ["nan", "inf", "-inf", "NaN,NaN", "nan,1", "1,inf", "-inf,inf", "1e999", "-1e999",
         "1e308", "99999999999999999999", "-99999999999999999999", "100000", "1000000000",
         "4294967296", "0", "-1", "", " ", ",", "1,", ",1", "1,2,3", "1x", "x1", "0x0", "1.5",
         "true", "none", "None", "null", "[]", "{}", "\x00", "é", "1" * 5000, "1e-400",
         "0,309", "-1000,1000", "1e5,1e6"]  # 0,309: 10**309 overflowed texture_nerf's check

values = st.one_of(
    st.sampled_from(NASTY),
    st.text(max_size=12),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(min_value=-2**70, max_value=2**70).map(str),
    st.tuples(st.floats(), st.floats()).map(lambda p: f"{p[0]},{p[1]}"),
)


def _check_refused_or_accepted(recipe_name, key, value):
    cls = RECIPES[recipe_name]
    opt = cls.options[key]
    try:
        opt.convert(value, cls.name)
    except OptionError as err:
        message = str(err)
        assert "\n" not in message and key in message, message
    else:  # a value the option accepts: building the recipe may only refuse with an OptionError
        try:
            cls(**{key: value})
        except OptionError as err:
            assert "\n" not in str(err), str(err)


@pytest.mark.parametrize("recipe_name,key", OPTIONS)
def test_nasty_values_are_refused_with_one_line(recipe_name, key, monkeypatch):
    monkeypatch.delenv(ALLOW_LARGE_ENV, raising=False)
    for value in NASTY:
        _check_refused_or_accepted(recipe_name, key, value)


# derandomized: the same 300 examples in every run, so CI is deterministic (a random run on a
# fresh clone found the 10**309 overflow now pinned in NASTY; turn derandomize off to explore)
@settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck),
          derandomize=True)
@given(st.sampled_from(OPTIONS), values)
def test_fuzz_set_values_of_every_recipe_option(option, value):
    _check_refused_or_accepted(*option, value)


@pytest.mark.parametrize("recipe_name,assignment", [
    ("movi_b", "size_range=nan,nan"), ("movi_f", "max_motion_blur=nan"),
    ("movi_e", "max_camera_movement=inf"), ("movi_a", "resolution=100000"),
    ("movi_a", "frame_end=1000000000"), ("movi_d", "settle_frames=100000000"),
    ("movi_a", "samples=100000"), ("movi_c", "size_range=1,1e9"),
])
def test_issue_values_are_refused_naming_the_value(recipe_name, assignment, monkeypatch):
    monkeypatch.delenv(ALLOW_LARGE_ENV, raising=False)
    key, _, value = assignment.partition("=")
    with pytest.raises(OptionError) as err:
        get_recipe(recipe_name).from_assignments([assignment])
    message = str(err.value)
    assert "\n" not in message and f"{key}={value!r}" in message, message


def test_default_bounds_are_lifted_explicitly(monkeypatch):
    movi_a = get_recipe("movi_a")
    monkeypatch.delenv(ALLOW_LARGE_ENV, raising=False)
    with pytest.raises(OptionError, match=f"{ALLOW_LARGE_ENV}=1"):
        movi_a.from_assignments(["resolution=10000x16"])
    assert "≤ 8192 (unless" in movi_a.options["resolution"].allowed()
    monkeypatch.setenv(ALLOW_LARGE_ENV, "1")
    assert movi_a.from_assignments(["resolution=10000x16"]).resolution == (10000, 16)
    assert movi_a.from_assignments(["frame_end=20000"]).frame_end == 20000
    with pytest.raises(OptionError, match="samples"):  # the hard bound stays
        movi_a.from_assignments(["samples=100000"])
    with pytest.raises(OptionError, match="finite"):  # and NaN is never a value
        get_recipe("movi_b").from_assignments(["size_range=1,nan"])


def kubric(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "kubric", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=120)


@pytest.mark.parametrize("args,needle", [
    (["worker", "movi_a", "--seed", "4294967296"], "4294967296"),
    (["worker", "movi_a", "--seed", "-1"], "-1"),
    (["generate", "movi_a", "--first-seed", "4294967295", "--scenes", "2"], "4294967296"),
    (["generate", "movi_a", "--scenes", "1", "--timeout", "-1"], "-1"),
    (["generate", "movi_a", "--scenes", "1", "--timeout", "0"], "0"),
    (["generate", "movi_a", "--scenes", "1", "--timeout", "nan"], "nan"),
    (["worker", "movi_b", "--seed", "0", "--set", "size_range=nan,nan"], "size_range"),
])
def test_cli_refuses_seeds_and_timeouts_before_running(args, needle, tmp_path):
    out = tmp_path / "out"
    r = kubric(*args, "--out", str(out))
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"kubric {args[0]}: error:"), r.stderr
    assert needle in lines[0] and "Traceback" not in r.stderr
    assert not out.exists()  # refused before anything ran
