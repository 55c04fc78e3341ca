"""Files are written atomically: a failure leaves the old file intact and no temporary behind."""

import json
import os

import pytest

from jaxlimb._io import atomic_open, write_json_atomic


def test_write_and_mode(tmp_path):
    p = tmp_path / "sub" / "a.json"
    write_json_atomic(p, {"x": 1})
    assert json.loads(p.read_text()) == {"x": 1}
    assert oct(os.stat(p).st_mode & 0o777) != "0o600"


def test_failure_keeps_old_file(tmp_path):
    p = tmp_path / "a.json"
    write_json_atomic(p, {"old": True})
    with pytest.raises(RuntimeError):
        with atomic_open(p) as fh:
            fh.write('{"new": tru')
            raise RuntimeError("interrupted")
    assert json.loads(p.read_text()) == {"old": True}
    assert sorted(x.name for x in tmp_path.iterdir()) == ["a.json"]
