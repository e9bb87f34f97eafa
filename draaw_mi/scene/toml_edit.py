"""A scene description written back into its own TOML file's text: only the values that
changed are edited, so the file's comments, order, blank lines and number spelling stay
(``draaw-mi fit -o fitted.toml``, :meth:`draaw_mi.scene.DraawScene.updated_text`).

Example::

    >>> text = "# studio\\n[materials.m]   # the ball\\nroughness = 0.5  # start\\nmetallic = 0\\n"
    >>> print(edited_toml(text, {"materials": {"m": {"roughness": 0.5, "metallic": 0}}},
    ...                   {"materials": {"m": {"roughness": 0.25, "metallic": 0}}}), end="")
    # studio
    [materials.m]   # the ball
    roughness = 0.25  # start
    metallic = 0
"""
from __future__ import annotations

import tomlkit


def edited_toml(text: str, old: dict, new: dict) -> str | None:
    """``text`` (a TOML document that reads as ``old``) with the values where ``new`` differs
    from ``old`` replaced, added or removed, and nothing else touched; ``None`` when ``text``
    does not read as ``old`` (the file changed since it was loaded: the caller writes ``new``
    in full instead)."""
    try:
        doc = tomlkit.parse(text)
    except Exception:  # noqa: BLE001 - tomlkit's parse errors share no base class with tomllib's
        return None
    if doc.unwrap() != old:
        return None
    _merge(doc, old, new)
    return tomlkit.dumps(doc)


def _merge(target, old, new) -> None:
    """Edit the tomlkit table or array ``target`` (whose plain value is ``old``) into ``new``
    (a dict for a table, a list of ``old``'s length for an array)."""
    if isinstance(new, dict):
        for key in [k for k in old if k not in new]:
            del target[key]
        pairs = [(key, old.get(key, _MISSING), value) for key, value in new.items()]
    else:
        pairs = [(i, before, after) for i, (before, after) in enumerate(zip(old, new))]
    for key, before, after in pairs:
        if before is not _MISSING and before == after:
            continue
        if _alike(before, after):
            _merge(target[key], before, after)
        else:
            target[key] = after


_MISSING = object()


def _alike(old, new) -> bool:
    """Whether ``new`` is edited into ``old`` in place (tables into tables, lists into lists
    of the same length: their comments and spelling stay) rather than replacing it whole."""
    if isinstance(old, dict) and isinstance(new, dict):
        return True
    return isinstance(old, list) and isinstance(new, list) and len(old) == len(new)
