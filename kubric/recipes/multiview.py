"""The multi-view recipes (importing this registers them): ``klevr`` and ``toybox``
(:mod:`kubric.recipes.klevr`), sharing :mod:`kubric.recipes.multiview_base`."""

from kubric.recipes import (  # noqa: F401
    complex_brdf,
    klevr,
    multiview_hdri,
    robust_nerf,
    svr,
    texture_nerf,
)
