"""Former name of :mod:`kubric.recipes`, kept so that ``import kubric.workers.movi`` still works."""

import sys

from kubric.recipes import movi, movi_base

sys.modules[__name__ + ".movi"] = movi
sys.modules[__name__ + ".movi_base"] = movi_base
