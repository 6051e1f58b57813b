"""Feature-by-feature comparison of an example read by a client library (``datasets``,
``webdataset``) with the loader's (:func:`kubric.datasets.load`)."""

import numpy as np

from kubric.datasets.tfds_io import flatten


def assert_same_value(name, got, want):
    """``got`` (as the client returned it) equals the loader's ``want``: the same values, read
    as ``want``'s dtype; ragged lists element by element; empty arrays only by their size."""
    if isinstance(want, str):
        assert got == want, name
        return
    if isinstance(want, list):
        assert len(got) == len(want), (name, len(got), len(want))
        for i, (g, w) in enumerate(zip(got, want, strict=True)):
            assert_same_value(f"{name}[{i}]", g, w)
        return
    want = np.asarray(want)
    got = np.asarray(got if not isinstance(got, np.ndarray) or got.dtype != object
                     else [np.asarray(g) for g in got])
    if want.size == 0:
        assert got.size == 0, (name, got.shape)
        return
    assert got.shape == want.shape, (name, got.shape, want.shape)
    if want.dtype.kind == "f":
        assert np.array_equal(got.astype(want.dtype), want, equal_nan=True), name
        assert got.dtype.kind == "f", (name, got.dtype)
    else:
        assert np.array_equal(got, want), name


def assert_same_example(got: dict, want: dict, names=None):
    """Every feature of the loader's example ``want`` (flat names) in the nested ``got``."""
    flat_got, flat_want = flatten(got), flatten(want)
    names = list(flat_want) if names is None else names
    missing = [n for n in names if n not in flat_got]
    assert not missing, missing
    for name in names:
        assert_same_value(name, flat_got[name], flat_want[name])
