"""Upstream Kubric's module path for the view base class: ``from kubric.core import view``.

The views live in :mod:`kubric.core.views`; this module only re-exports them.
"""

from kubric.core.views import TableView, View

__all__ = ["View", "TableView"]
