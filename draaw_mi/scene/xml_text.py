"""Mitsuba XML files read with :mod:`xml.etree.ElementTree`, as leniently as Mitsuba reads them.

Mitsuba parses scene files with pugixml, which accepts a comment holding ``--`` (for example
``<!-- render it with --version v4 -->``); the XML standard, and so ElementTree, refuses it. A
file Mitsuba loads must not fail here: :func:`parse_xml_text` and :func:`parse_xml_file` parse
the text as it is and, where that fails, once more with its comments removed (draaw-mi reads
no comment). Any other error is the file's own and is raised as it was.

>>> root = parse_xml_text('<!-- draaw-mi render --version v4 --><scene version="3.0.0"/>')
>>> root.tag
'scene'
"""
from __future__ import annotations

import re
import xml.etree.ElementTree as ET

_COMMENT = re.compile(r"<!--.*?-->", re.S)


def without_comments(text: str) -> str:
    """``text`` with its ``<!-- ... -->`` comments removed."""
    return _COMMENT.sub("", text)


def parse_xml_text(text: str) -> ET.Element:
    """The root element of the XML ``text``; :class:`xml.etree.ElementTree.ParseError` where
    neither the text nor the text without its comments parses (the error of the text as it is)."""
    try:
        return ET.fromstring(text)
    except ET.ParseError as first:
        stripped = without_comments(text)
        if stripped == text:
            raise
        try:
            return ET.fromstring(stripped)
        except ET.ParseError:
            raise first from None


def parse_xml_file(path: str) -> ET.Element:
    """:func:`parse_xml_text` of the file ``path`` (UTF-8); ``OSError`` / ``UnicodeDecodeError``
    where it cannot be read."""
    with open(path, encoding="utf-8") as fh:
        return parse_xml_text(fh.read())


__all__ = ["parse_xml_file", "parse_xml_text", "without_comments"]
