"""The Post tab of :class:`~draaw_mi.widgets.MaterialTuner`: add, remove, reorder and scale
the filters of the post chain, or edit the chain as JSON.

:class:`PostPanel` owns the chain (``chain``: a list of filter tables, every parameter at the
top level) and its widgets; :func:`close_widgets` closes a panel's widgets for good.
"""
from __future__ import annotations

import json

import ipywidgets as W

from .. import post
from ..errors import DraawError
from .camera_panel import slider as _slider

#: what the Post tab's "add" starts a filter with, where amount 0.5 of its defaults shows nothing
#: (contrast 1.0) or something neither linear nor encoded (half an sRGB encoding)
_POST_START = {"contrast": {"contrast": 2.0}, "srgb": {"amount": 1.0}}


def close_widgets(*roots) -> None:
    """Close ``roots`` and every widget under them (children, layouts, styles; dicts of
    widgets are walked too). ipywidgets keeps each open widget in a global registry and a
    box's ``close()`` leaves its children open, so without this a closed panel stays alive
    with its callbacks, its tuner and the tuner's scene -- and every live draaw material
    enlarges the BSDF calls of all later renders (vcalls cover every live instance)."""
    seen, stack = set(), list(roots)
    while stack:
        w = stack.pop()
        if isinstance(w, dict):
            stack.extend(w.values())
            continue
        if id(w) in seen or not isinstance(w, W.Widget):
            continue
        seen.add(id(w))
        stack.extend(getattr(w, "children", ()))
        stack.extend(getattr(w, name, None) for name in ("layout", "style"))
        w.close()


class PostPanel:
    """The tuner's post-chain controls (see the module docstring).

    ================  ==========================================================================
    Given             Used for
    ================  ==========================================================================
    ``chain``         the chain to start from (a list of filter tables)
    ``guard(fn)``     a control's action wrapped so that an error shows in red, not raised
    ``configure(c)``  hand the preview a new chain (``configure(post=chain)``)
    ``syncing``       a context manager in which widget changes apply nothing
    ================  ==========================================================================
    """

    def __init__(self, chain, *, guard, configure, syncing):
        self._configure, self._syncing, self._guard = configure, syncing, guard
        self.chain = list(chain)
        self.post_rows = W.VBox([])
        self.post_add = W.Dropdown(options=list(post.FILTERS), description="filter")
        add = W.Button(description="add")
        add.on_click(guard(lambda _b: self.edit(add=self.post_add.value)))
        self.post_json = W.Textarea(value=json.dumps(self.chain), layout=W.Layout(width="380px", height="80px"))
        apply = W.Button(description="apply JSON")
        apply.on_click(guard(lambda _b: self.from_json(self.post_json.value)))
        self._refresh_rows()
        self.widget = W.VBox([self.post_rows, W.HBox([self.post_add, add]), self.post_json, apply])

    def from_json(self, text):
        try:
            chain = json.loads(text)
        except json.JSONDecodeError as e:
            raise DraawError(f"post chain JSON: {e}") from None
        if not isinstance(chain, list):
            raise DraawError(f"post chain JSON: expected a list of filter tables, got {type(chain).__name__}")
        self.set_chain(chain)

    def set_chain(self, chain):
        """Validate ``chain`` (:class:`~draaw_mi.errors.ParameterError`), keep it in one form
        (every parameter at the top level, as the sliders write them) and hand it on."""
        self.chain = post.Chain(chain).to_list()
        self._configure(post=self.chain)
        self._refresh_rows()

    def edit(self, add=None, remove=None, up=None, amount=None):
        """Add a filter (by name), remove one, move one up, or set one's amount."""
        chain = [dict(e) for e in self.chain]
        if add is not None:             # a start that shows: contrast 1 is the identity
            chain.append({"type": add, "amount": 0.5, **_POST_START.get(add, {})})
        if remove is not None:
            chain.pop(remove)
        if up is not None and up > 0:
            chain[up - 1], chain[up] = chain[up], chain[up - 1]
        if amount is not None:
            chain[amount[0]]["amount"] = float(amount[1])
        self.set_chain(chain)

    def _refresh_rows(self):
        rows = []
        for i, e in enumerate(self.chain):
            amt = _slider(str(e.get("type")), float(e.get("amount", 1.0)), 0.0, 1.0)
            amt.continuous_update = False
            amt.observe(self._guard(lambda ch, i=i: self.edit(amount=(i, ch["new"]))), "value")
            upb = W.Button(description="↑", layout=W.Layout(width="36px"))
            upb.on_click(self._guard(lambda _b, i=i: self.edit(up=i)))
            rm = W.Button(description="✕", layout=W.Layout(width="36px"))
            rm.on_click(self._guard(lambda _b, i=i: self.edit(remove=i)))
            rows.append(W.HBox([amt, upb, rm]))
        old = self.post_rows.children
        self.post_rows.children = rows
        close_widgets(*old)                 # replaced rows: out of the registry
        with self._syncing():
            self.post_json.value = json.dumps(self.chain)
