"""Atomic writes: the target holds the old content or the new, never a part, and no
temporary file is left behind."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from autonomy.common.files import atomic_path, atomic_write, atomic_write_text


def _names(d) -> list[str]:
    return sorted(os.listdir(d))


def test_text_and_binary_round_trip(tmp_path) -> None:
    t = atomic_write_text(tmp_path / "a.json", "{\"é\": 1}\n")
    assert t == tmp_path / "a.json"
    assert t.read_bytes() == "{\"é\": 1}\n".encode()
    a = np.arange(12, dtype=np.int16).reshape(3, 4)
    b = atomic_write(str(tmp_path / "b.npz"), lambda f: np.savez_compressed(f, a=a))
    with np.load(b) as z:
        np.testing.assert_array_equal(z["a"], a)
    assert _names(tmp_path) == ["a.json", "b.npz"]


def test_replaces_an_existing_file_whole(tmp_path) -> None:
    p = tmp_path / "x.bin"
    p.write_bytes(b"old content that is longer than the new")
    atomic_write(p, lambda f: f.write(b"new"))
    assert p.read_bytes() == b"new"
    assert _names(tmp_path) == ["x.bin"]


class Boom(Exception):
    pass


@pytest.mark.parametrize("exc", [Boom, KeyboardInterrupt])
def test_a_failing_writer_leaves_nothing(tmp_path, exc) -> None:
    def write(f) -> None:
        f.write(b"half")
        raise exc

    with pytest.raises(exc):
        atomic_write(tmp_path / "new.bin", write)
    assert _names(tmp_path) == []

    old = tmp_path / "old.bin"
    old.write_bytes(b"untouched")
    with pytest.raises(exc):
        atomic_write(old, write)
    assert old.read_bytes() == b"untouched"
    assert _names(tmp_path) == ["old.bin"]


def test_atomic_path_by_name(tmp_path) -> None:
    p = tmp_path / "m.npy"
    with atomic_path(p) as tmp:
        assert tmp.parent == tmp_path and tmp.is_file() and tmp.stat().st_size == 0
        assert not p.exists()
        mm = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.uint16, shape=(2, 3))
        mm[:] = 7
        mm.flush()
        del mm
    assert (np.load(p) == 7).all() and _names(tmp_path) == ["m.npy"]

    with pytest.raises(Boom), atomic_path(p) as tmp:
        tmp.write_bytes(b"partial")
        raise Boom
    assert (np.load(p) == 7).all() and _names(tmp_path) == ["m.npy"]


def test_a_missing_directory_is_an_oserror(tmp_path) -> None:
    with pytest.raises(FileNotFoundError):
        atomic_write_text(tmp_path / "no" / "such.txt", "x")
    assert _names(tmp_path) == []


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_mode_is_that_of_a_plain_new_file(tmp_path, umask) -> None:
    old = os.umask(umask)
    try:
        p = atomic_write_text(tmp_path / "shared.txt", "x")
        with open(tmp_path / "plain.txt", "w") as f:  # the reference: what open() makes
            f.write("x")
    finally:
        os.umask(old)
    mode = stat.S_IMODE(p.stat().st_mode)
    assert mode == 0o666 & ~umask
    assert mode == stat.S_IMODE((tmp_path / "plain.txt").stat().st_mode)


def test_output_path_makes_the_directory_and_refuses_what_cannot_be_written(tmp_path) -> None:
    from autonomy.common.errors import InputError
    from autonomy.common.files import output_path

    assert output_path(tmp_path / "a" / "b.json") == tmp_path / "a" / "b.json" and (tmp_path / "a").is_dir()
    assert output_path(tmp_path / "run", directory=True).is_dir()
    (tmp_path / "f").write_text("x")
    with pytest.raises(InputError, match=r"^--out .*: is a directory"):
        output_path(tmp_path / "run", "--out")
    with pytest.raises(InputError, match=r"^out .*: cannot make the directory"):
        output_path(tmp_path / "f" / "x.json")
    with pytest.raises(InputError, match="cannot make the directory"):
        output_path(tmp_path / "f" / "d", directory=True)
