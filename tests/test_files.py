"""File helpers (:mod:`jaxmatch.files`): bounded reads."""

from __future__ import annotations

import os
import threading

import pytest

from jaxmatch import files
from jaxmatch.errors import InputError
from jaxmatch.files import read_limited


@pytest.mark.parametrize("size, limit", [(0, 10), (1, 10), (10, 10), (11, 10), (5000, 4096), (3 * (1 << 16) + 7, 1 << 20),
                                         (3 * (1 << 16) + 7, 3 * (1 << 16) + 6)])
def test_a_file_reads_whole_up_to_the_limit_and_is_refused_beyond(tmp_path, size, limit):
    data = os.urandom(size)
    p = tmp_path / "f.bin"
    p.write_bytes(data)
    if size <= limit:
        assert read_limited(p, limit) == data
    else:
        with pytest.raises(InputError, match=f"f.bin: file is larger than {limit} bytes"):
            read_limited(p, limit)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no named pipes")
@pytest.mark.parametrize("size, limit", [(0, 100), (70_000, 200_000), (70_000, 69_999)])
def test_a_pipe_that_reports_no_size_reads_in_pieces(tmp_path, size, limit):
    """A named pipe reports size 0: its bytes are read in pieces all the same, at most ``limit``
    of them (the writer's end is closed either way)."""
    data = os.urandom(size)
    p = tmp_path / "pipe"
    os.mkfifo(p)

    def write():
        with open(p, "wb") as fh:
            try:
                fh.write(data)
            except BrokenPipeError:
                pass

    writer = threading.Thread(target=write)
    writer.start()
    try:
        if size <= limit:
            assert read_limited(p, limit) == data
        else:
            with pytest.raises(InputError, match="larger than"):
                read_limited(p, limit)
    finally:
        writer.join(timeout=10)
    assert size > files._PIECE or size == 0


def test_a_missing_file_or_a_folder_is_one_line(tmp_path):
    with pytest.raises(InputError, match="cannot read lattice file"):
        read_limited(tmp_path / "none.toml", 10, "lattice file")
    with pytest.raises(InputError, match="cannot read"):
        read_limited(tmp_path, 10)
