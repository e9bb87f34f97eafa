"""Reading scene documents (draaw_mi.scene.schema.read_document)."""
from __future__ import annotations

import pytest

from draaw_mi.scene.schema import read_document


@pytest.mark.parametrize("name, text", [
    ("s.toml", '[render]\nresolution = [8, 8]\n[[shapes]]\ntype = "sphere"\n'),
    ("s.json", '{"render": {"resolution": [8, 8]}, "shapes": [{"type": "sphere"}]}'),
])
def test_a_file_starting_with_a_utf8_byte_order_mark_reads_as_without_it(tmp_path, name, text):
    # (Windows editors write the mark; it is not part of the text)
    path = tmp_path / name
    path.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    doc = read_document(str(path))
    assert doc["render"]["resolution"] == [8, 8] and doc["shapes"] == [{"type": "sphere"}]
