"""The Post tab of :class:`~draaw_mi.widgets.MaterialTuner`: add, remove, reorder and scale
the filters of the post chain, or edit the chain as JSON.

A mixin: it reads the tuner's ``post`` (the chain as a list of tables), ``_configure``,
``_guard`` and ``_syncing``.
"""
from __future__ import annotations

import json

import ipywidgets as W

from .errors import DraawError
from .tuner_camera import slider as _slider

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
    """The tuner's post-chain controls (see the module docstring)."""

    def _post_panel(self):
        from . import post
        self.post_rows = W.VBox([])
        self.post_add = W.Dropdown(options=list(post.FILTERS), description="filter")
        add = W.Button(description="add")
        add.on_click(self._guard(lambda _b: self._post_edit(add=self.post_add.value)))
        self.post_json = W.Textarea(value=json.dumps(self.post), layout=W.Layout(width="380px", height="80px"))
        apply = W.Button(description="apply JSON")
        apply.on_click(self._guard(lambda _b: self._post_from_json(self.post_json.value)))
        self._post_rows_refresh()
        return W.VBox([self.post_rows, W.HBox([self.post_add, add]), self.post_json, apply])

    def _post_from_json(self, text):
        try:
            chain = json.loads(text)
        except json.JSONDecodeError as e:
            raise DraawError(f"post chain JSON: {e}") from None
        if not isinstance(chain, list):
            raise DraawError(f"post chain JSON: expected a list of filter tables, got {type(chain).__name__}")
        self._set_post(chain)

    def _set_post(self, chain):
        from . import post
        # validated (ParameterError) and in one form: every parameter at the top level (an
        # entry written with "params": {...} showed amount 1.0 and refused the slider's value)
        self.post = post.Chain(chain).to_list()
        self._configure(post=self.post)
        self._post_rows_refresh()

    def _post_edit(self, add=None, remove=None, up=None, amount=None):
        chain = [dict(e) for e in self.post]
        if add is not None:             # (a start that shows: contrast 1 is the identity)
            chain.append({"type": add, "amount": 0.5, **_POST_START.get(add, {})})
        if remove is not None:
            chain.pop(remove)
        if up is not None and up > 0:
            chain[up - 1], chain[up] = chain[up], chain[up - 1]
        if amount is not None:
            chain[amount[0]]["amount"] = float(amount[1])
        self._set_post(chain)

    def _post_rows_refresh(self):
        rows = []
        for i, e in enumerate(self.post):
            amt = _slider(str(e.get("type")), float(e.get("amount", 1.0)), 0.0, 1.0)
            amt.continuous_update = False
            amt.observe(self._guard(lambda ch, i=i: self._post_edit(amount=(i, ch["new"]))), "value")
            upb = W.Button(description="↑", layout=W.Layout(width="36px"))
            upb.on_click(self._guard(lambda _b, i=i: self._post_edit(up=i)))
            rm = W.Button(description="✕", layout=W.Layout(width="36px"))
            rm.on_click(self._guard(lambda _b, i=i: self._post_edit(remove=i)))
            rows.append(W.HBox([amt, upb, rm]))
        if hasattr(self, "post_rows"):
            old = self.post_rows.children
            self.post_rows.children = rows
            close_widgets(*old)                 # replaced rows: out of the registry
            self._syncing = True
            try:
                self.post_json.value = json.dumps(self.post)
            finally:
                self._syncing = False
