"""All-or-nothing writing (``montecarlo.io.files``), in process: permissions by the umask, the
list of written files, the refusals of :class:`OutputDir` and :func:`writable_file` in full,
the lock, stale staging directories, and figures that render to the same bytes.

The command-line view of the same rules is ``tests/test_output_safety.py``.
"""

import hashlib
import json
import os
import stat
from pathlib import Path

import pytest

from montecarlo.errors import InputError
from montecarlo.io import files
from montecarlo.io.files import PROVENANCE, OutputDir, OutputLock


@pytest.fixture
def umask_027():
    old = os.umask(0o027)
    yield
    os.umask(old)


@pytest.fixture
def umask_022():
    old = os.umask(0o022)
    yield
    os.umask(old)


def _mode(path):
    return stat.S_IMODE(os.stat(path).st_mode)


def _refused(call, *args):
    with pytest.raises(InputError) as info:
        call(*args)
    assert "\n" not in str(info.value)
    return str(info.value)


def test_with_umask_and_atomic_write_permissions(tmp_path, umask_027):
    """0o666 & ~0o027 = 0o640; 0o777 & ~0o027 = 0o750; the umask is left as it was."""
    assert files.with_umask(0o666) == 0o640 and files.with_umask(0o777) == 0o750
    assert os.umask(0o027) == 0o027
    p = tmp_path / "a.txt"
    files.atomic_write_bytes(p, b"first")
    files.atomic_write_bytes(str(p), b"second")
    assert p.read_bytes() == b"second" and _mode(p) == 0o640
    assert [x.name for x in tmp_path.iterdir()] == ["a.txt"]


def test_atomic_write_stages_beside_the_target_with_the_usual_mode(tmp_path, umask_022,
                                                                    monkeypatch):
    """The temporary file is ``.NAME.<random>.tmp`` in the target's directory (a rename
    within one file system); the file ends as 0o666 & ~0o022 = 0o644."""
    renames = []
    real = os.replace
    monkeypatch.setattr(files.os, "replace", lambda a, b: (renames.append((a, b)), real(a, b)))
    p = tmp_path / "a.txt"
    files.atomic_write_bytes(p, b"x")
    (src, dst), = renames
    assert Path(src).parent == tmp_path and Path(dst) == p
    assert Path(src).name.startswith(".a.txt.") and Path(src).name.endswith(".tmp")
    assert _mode(p) == 0o644


def test_a_failed_atomic_write_leaves_neither_file_nor_temporary(tmp_path):
    target = tmp_path / "sub"
    target.mkdir()  # a directory: the rename fails
    with pytest.raises(OSError):
        files.atomic_write_bytes(target, b"x")
    assert [x.name for x in tmp_path.iterdir()] == ["sub"] and not any(target.iterdir())


def test_written_files_lists_sizes_directories_and_links(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "x.bin").write_bytes(b"12345")
    (tmp_path / "a.txt").write_bytes(b"ab")
    (tmp_path / PROVENANCE).write_text("{}")
    (tmp_path / "d" / PROVENANCE).write_text("{}")  # only the top one is the marker
    (tmp_path / "link").symlink_to(tmp_path / "a.txt")
    assert files.written_files(tmp_path) == {"a.txt": 2, "d": None, "d/provenance.json": 2,
                                             "d/x.bin": 5, "link": -1}
    assert list(files.written_files(tmp_path)) == sorted(files.written_files(tmp_path))


def test_record_and_update_the_list_of_written_files(tmp_path):
    files.record_written_files(tmp_path)  # no marker: nothing
    assert not (tmp_path / PROVENANCE).exists()
    (tmp_path / PROVENANCE).write_text("[1, 2]")  # not a dict: left alone
    files.record_written_files(tmp_path)
    files.update_written_files(tmp_path, ("a",))
    assert (tmp_path / PROVENANCE).read_text() == "[1, 2]"
    (tmp_path / PROVENANCE).write_text("not json")
    files.record_written_files(tmp_path)
    files.update_written_files(tmp_path, ("a",))
    assert (tmp_path / PROVENANCE).read_text() == "not json"
    (tmp_path / PROVENANCE).write_text(json.dumps({"kind": "run"}))
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "f").write_bytes(b"123")
    (tmp_path / "b.txt").write_bytes(b"1")
    files.update_written_files(tmp_path, ("a",))  # no list yet: none is made
    assert json.loads((tmp_path / PROVENANCE).read_text()) == {"kind": "run"}
    files.record_written_files(tmp_path)
    text = (tmp_path / PROVENANCE).read_text()
    assert text.endswith("}\n") and '\n  "kind": "run"' in text
    sha = lambda data: hashlib.sha256(data).hexdigest()  # noqa: E731
    sealed = sha(b'{"kind":"run"}')  # the record but its lists, as canonical JSON
    assert json.loads(text) == {"kind": "run", "files": {"a": None, "a/f": 3, "b.txt": 1},
                                "sha256": {"a/f": sha(b"123"), "b.txt": sha(b"1")},
                                "record_sha256": sealed}
    (tmp_path / "a" / "f").write_bytes(b"123456")
    (tmp_path / "a" / "g").write_bytes(b"")
    (tmp_path / "b.txt").write_bytes(b"1234")  # not among the replaced: its old size is kept
    files.update_written_files(tmp_path, ("a",))
    text = (tmp_path / PROVENANCE).read_text()
    assert text.endswith("}\n") and '\n  "kind": "run"' in text
    assert json.loads(text) == {"kind": "run",
                                "files": {"a": None, "a/f": 6, "a/g": 0, "b.txt": 1},
                                "sha256": {"a/f": sha(b"123456"), "a/g": sha(b""),
                                           "b.txt": sha(b"1")},
                                "record_sha256": sealed}
    (tmp_path / "a" / "g").unlink()  # removed from a replaced entry: gone from the list
    files.update_written_files(tmp_path, ("a",))
    assert json.loads((tmp_path / PROVENANCE).read_text())["files"] == {
        "a": None, "a/f": 6, "b.txt": 1}
    (tmp_path / "a" / "g").write_bytes(b"")
    assert files.foreign_entries(tmp_path, json.loads(text)) == ["b.txt"]
    assert files.foreign_entries(tmp_path, {"files": [1]}) is None
    (tmp_path / "new").write_bytes(b"")
    (tmp_path / "a" / "g").unlink()
    (tmp_path / "a" / "g").symlink_to(tmp_path / "b.txt")
    record = {"files": {"a": None, "a/f": 6, "a/g": -1, "b.txt": 4}}
    assert files.foreign_entries(tmp_path, record) == ["a/g", "new"]  # a link is never ours


def test_protected_paths_and_their_reasons(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "study.toml").write_text("")
    assert files.protected_reason(Path(".")) == "is the current directory or one of its parents"
    assert files.protected_reason(tmp_path.parent) == (
        "is the current directory or one of its parents")
    assert files.protected_reason(Path("results")) == (
        "is the results root 'results' or one of its parents, not a result")
    assert files.protected_reason(Path("results") / "study") is None
    assert files.protected_reason(Path("work"), (Path("work/study.toml"),)) == (
        "holds the input 'work/study.toml'")
    assert files.protected_reason(Path("work/out"), (Path("work/study.toml"),)) is None
    (tmp_path / "ln").symlink_to(tmp_path / "work")
    assert files.protected_reason(Path("ln")) == "is a symbolic link; give the directory itself"
    monkeypatch.setenv("HOME", str(tmp_path / "work"))
    assert files.protected_reason(Path("work")) == "is the home directory"
    assert files.protected_reason(Path("work/out")) is None


def test_output_dir_refusals_in_full(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    out = tmp_path / "out"
    assert _refused(OutputDir(tmp_path, "run").check) == (
        f"{tmp_path}: is the current directory or one of its parents; choose another output path")
    out.write_text("x")
    assert _refused(OutputDir(out, "run").check) == (
        f"{out}: exists and is not a directory; choose another output path")
    out.unlink()
    out.mkdir()
    OutputDir(out, "run").check()  # empty: fine
    (out / PROVENANCE).write_text(json.dumps({"kind": "run", "study": "a"}))
    assert _refused(OutputDir(out, "run", {"study": "b"}).check) == (
        f"{out}: exists and is not an earlier result of this command (kind=run study=b); "
        "choose another output path or remove it")
    assert _refused(OutputDir(out, "other").check) == (
        f"{out}: exists and is not an earlier result of this command (kind=other); "
        "choose another output path or remove it")
    assert _refused(OutputDir(out, "run", {"study": "a"}).check) == (
        f"{out}: an earlier result without the list of its files (written by an older "
        "version), so files added to it cannot be told apart; choose another output path or "
        "remove it")
    (out / "mine.txt").write_text("abc")
    (out / PROVENANCE).write_text(json.dumps({"kind": "run", "study": "a", "files": {}}))
    assert _refused(OutputDir(out, "run", {"study": "a"}).check) == (
        f"{out}: holds 1 file(s) this command did not write (first 'mine.txt'), so it is not "
        "wholly an earlier result; choose another output path or move them out")
    study = out / "study.toml"
    assert _refused(OutputDir(out, "run", inputs=(str(study),)).check) == (
        f"{out}: holds the input '{study}'; choose another output path")
    (out / PROVENANCE).write_text("[]")
    assert "is not an earlier result" in _refused(OutputDir(out, "run").check)
    (out / PROVENANCE).write_text(json.dumps({"kind": "run", "files": {"mine.txt": 3}}))
    d = OutputDir(out, "run")
    d.check()
    assert d.previous == out


def test_output_dir_writes_all_or_nothing_and_lists_its_files(tmp_path, umask_027):
    out = tmp_path / "a" / "b" / "out"
    with OutputDir(out, "run") as staging:
        assert staging.parent == out.parent and staging.name.startswith(f".out.tmp-{os.getpid()}-")
        assert _mode(staging) == 0o750
        assert (out.parent / ".out.lock").exists()
        (staging / PROVENANCE).write_text(json.dumps({"kind": "run"}))
        (staging / "r.txt").write_text("12")
    assert sorted(x.name for x in out.parent.iterdir()) == ["out"]
    assert json.loads((out / PROVENANCE).read_text())["files"] == {"r.txt": 2}
    with OutputDir(out, "run") as staging:  # an earlier result of the same kind: replaced
        (staging / PROVENANCE).write_text(json.dumps({"kind": "run"}))
        (staging / "s.txt").write_text("1")
    assert sorted(x.name for x in out.iterdir()) == [PROVENANCE, "s.txt"]
    assert sorted(x.name for x in out.parent.iterdir()) == ["out"]
    with pytest.raises(KeyError), OutputDir(out, "run") as staging:
        (staging / "t.txt").write_text("1")
        raise KeyError("stop")
    assert sorted(x.name for x in out.iterdir()) == [PROVENANCE, "s.txt"]
    assert sorted(x.name for x in out.parent.iterdir()) == ["out"]
    fresh = tmp_path / "c" / "d" / "out"
    with pytest.raises(KeyError), OutputDir(fresh, "run"):
        raise KeyError("stop")
    assert not (tmp_path / "c").exists()  # the directories made for it are gone again
    with pytest.raises(KeyError), OutputDir(fresh, "run"):
        (tmp_path / "c" / "other.txt").write_text("")  # someone else's file: c is kept
        raise KeyError("stop")
    assert sorted(x.name for x in (tmp_path / "c").iterdir()) == ["other.txt"]
    (tmp_path / "file").write_text("")
    below_a_file = tmp_path / "file" / "out"
    assert _refused(OutputDir(below_a_file, "run").__enter__) == (
        f"{below_a_file}: cannot write here (File exists)")


def test_the_old_result_is_moved_aside_beside_it_before_removal(tmp_path, monkeypatch):
    made = []
    real = files.tempfile.mkdtemp
    monkeypatch.setattr(files.tempfile, "mkdtemp",
                        lambda **kw: (made.append(kw), real(**kw))[1])
    out = tmp_path / "out"
    for _ in range(2):
        with OutputDir(out, "run") as staging:
            (staging / PROVENANCE).write_text(json.dumps({"kind": "run"}))
    assert [m["dir"] for m in made] == [tmp_path] * 3
    assert made[1]["prefix"] == f".out.tmp-{os.getpid()}-"
    assert made[2]["prefix"] == f".out.old-{os.getpid()}-"
    assert sorted(x.name for x in tmp_path.iterdir()) == ["out"]


def test_a_second_writer_is_refused_and_a_free_lock_is_taken(tmp_path):
    out = tmp_path / "out"
    with OutputLock(out) as lock:
        assert lock.file == tmp_path / ".out.lock"
        assert lock.file.read_text() == f"{os.getpid()}\n"
        message = _refused(OutputLock(out).__enter__)
        assert message == (f"{out}: another process (pid {os.getpid()}) is writing it (lock "
                           ".out.lock); wait for it to finish or choose another output path")
        assert _refused(OutputDir(out, "run").__enter__) == message
    assert not (tmp_path / ".out.lock").exists() and lock.fd is None
    (tmp_path / ".out.lock").write_text("99999999\n")  # left by a killed writer: taken over
    with OutputLock(out) as lock:
        assert lock.file.read_text() == f"{os.getpid()}\n"
    import fcntl

    fd = os.open(tmp_path / ".out.lock", os.O_RDWR | os.O_CREAT | os.O_TRUNC)
    try:  # held by a writer that has not yet written its pid
        fcntl.flock(fd, fcntl.LOCK_EX)
        assert "another process (pid ?) is writing it" in _refused(OutputLock(out).__enter__)
    finally:
        os.close(fd)
    missing = tmp_path / "no" / "out"
    assert _refused(OutputLock(missing).__enter__).startswith(f"{missing}: cannot write here (")


def test_stale_staging_of_dead_processes_only_is_removed(tmp_path):
    dead = 2**22 + 12345  # above the kernel's pid_max of 4194304: no such process
    assert not files._pid_alive(dead) and files._pid_alive(os.getpid())
    names = [f".out.tmp-{dead}-abc", f".out.old-{dead}-abc", f".out.tmp-{os.getpid()}-abc",
             f".out.new-{dead}-abc", ".out.tmp-x1-abc", f".other.tmp-{dead}-abc"]
    for name in names:
        (tmp_path / name).mkdir()
    OutputDir(tmp_path / "out", "run")._remove_stale()
    assert sorted(x.name for x in tmp_path.iterdir()) == sorted(names[2:])


def test_writable_file_refusals_in_full(tmp_path, monkeypatch):
    assert _refused(files.writable_file, tmp_path) == (
        f"{tmp_path}: is a directory; give a file name")
    p = tmp_path / "no" / "f.txt"
    assert _refused(files.writable_file, p) == f"{p}: no such directory '{tmp_path / 'no'}'"
    assert files.writable_file(str(tmp_path / "f.txt")) == tmp_path / "f.txt"
    monkeypatch.chdir(tmp_path)
    assert files.writable_file("g.txt") == Path("g.txt")
    # root may write anywhere: os.access is replaced by one that refuses writing to ``ro``
    # (a directory, asked for write and search) and to the existing file ``ro.txt``
    ro, ro_file = tmp_path / "ro", tmp_path / "ro.txt"
    ro.mkdir()
    ro_file.write_text("")

    def access(path, mode):
        if Path(path) == ro:
            return mode & os.W_OK == 0 or mode & os.X_OK == 0
        return not (Path(path) == ro_file and mode & os.W_OK)

    monkeypatch.setattr(files.os, "access", access)
    assert _refused(files.writable_file, ro / "f") == f"{ro / 'f'}: not writable"
    assert _refused(files.writable_file, ro_file) == f"{ro_file}: not writable"
    assert files.writable_file(tmp_path / "new.txt") == tmp_path / "new.txt"


def _laid_out_figure():
    """A figure whose layout matters: constrained layout, shared axes, a colorbar, titles, a
    legend and a rasterised mesh, as the study plots have."""
    import numpy as np
    from matplotlib.figure import Figure

    fig = Figure(figsize=(4, 2.5), layout="constrained")
    left, right = fig.subplots(1, 2, sharey=True)
    left.plot(np.arange(5.0), np.arange(5.0) ** 2, "-o", ms=3, label="square")
    left.set_title("a title that takes room", fontsize=8)
    left.legend(fontsize=6)
    mesh = right.pcolormesh(np.arange(12.0).reshape(3, 4), rasterized=True)
    fig.colorbar(mesh, ax=right, label="value [mrad]")
    fig.suptitle("two panels\nover two lines")
    return fig


def test_figure_bytes_are_savefigs_drawn_once():
    """figure_bytes gives matplotlib's own savefig bytes, png then svg then pdf from one figure
    as a report draws them (each layout starting where the previous one ended), drawing the
    figure once per format where savefig draws it twice; the figure is left as it was."""
    import io

    import matplotlib

    reference = _laid_out_figure()
    expected = []
    for fmt, dpi, salt in (("png", 110, "x"), ("svg", None, "y"), ("pdf", 90, "x")):
        buf = io.BytesIO()
        with matplotlib.rc_context({"svg.hashsalt": salt, "svg.fonttype": "none"}):
            reference.savefig(buf, format=fmt, dpi=dpi, metadata=files.FIXED_METADATA[fmt] or None)
        expected.append(buf.getvalue())
    fig = _laid_out_figure()
    engine, canvas, dpi = fig.get_layout_engine(), fig.canvas, fig.dpi
    draws = []
    draw = fig.draw
    fig.draw = lambda renderer: (draws.append(renderer), draw(renderer))
    got = [files.figure_bytes(fig, "png", 110, rc={"svg.hashsalt": "x"}),
           files.figure_bytes(fig, "svg", None, rc={"svg.hashsalt": "y", "svg.fonttype": "none"}),
           files.figure_bytes(fig, "pdf", 90, rc={"svg.hashsalt": "x"})]
    assert [g == e for g, e in zip(got, expected, strict=True)] == [True, True, True]
    assert len(draws) == 3  # savefig itself: 6 (a pass with drawing disabled before each)
    assert (fig.get_layout_engine(), fig.canvas, fig.dpi) == (engine, canvas, dpi)
    draws.clear()
    draw_reference = reference.draw
    reference.draw = lambda renderer: (draws.append(renderer), draw_reference(renderer))
    reference.savefig(io.BytesIO(), format="png")
    assert len(draws) == 2
    with pytest.raises(ValueError, match="not supported"):  # savefig's own refusal
        files.figure_bytes(fig, "xyz")


def test_figures_render_to_the_same_bytes(tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(2, 2))
    ax.plot([0, 1], [1, 0])
    try:
        svg = files.figure_bytes(fig, "svg")
        assert svg == files.figure_bytes(fig, "svg") and b"<dc:date>" not in svg
        pdf = files.figure_bytes(fig, "pdf")
        assert pdf.startswith(b"%PDF") and b"CreationDate" not in pdf
        png = files.save_figure(fig, tmp_path / "f.png", dpi=50)
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert png.read_bytes() == files.figure_bytes(fig, "png", 50)
        assert _png_size(png.read_bytes()) == (100, 100)  # 2 in at 50 dpi
        assert _png_size(files.figure_bytes(fig)) == (220, 220)  # 2 in at the default 110 dpi
        default = files.save_figure(fig, tmp_path / "f")
        assert _png_size(default.read_bytes()) == (220, 220)
        assert files.save_figure(fig, tmp_path / "f.svg").read_bytes().lstrip().startswith(b"<?xml")
    finally:
        plt.close(fig)


def _png_size(data):
    """Width and height from a PNG's IHDR chunk (bytes 16-24, big-endian)."""
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def test_lock_file_mode_and_a_lock_file_removed_meanwhile(tmp_path, umask_022):
    """The lock file gets 0o666 & ~0o022 = 0o644; a lock file removed by someone else while
    held is no error on exit."""
    out = tmp_path / "out"
    with OutputLock(out) as lock:
        assert _mode(lock.file) == 0o644
        lock.file.unlink()
    assert lock.fd is None


def test_staging_details_on_failure_and_before_the_first_result(tmp_path):
    """An absent path has no previous result; a body that removed its own staging directory
    before failing still fails with its own error; a stale entry that is a file (not a
    directory) is left alone without an error."""
    out = tmp_path / "out"
    d = OutputDir(out, "run")
    d.check()
    assert d.previous is None
    with pytest.raises(KeyError), OutputDir(out, "run") as staging:
        staging.rmdir()
        raise KeyError("stop")
    dead = 2**22 + 12345
    (tmp_path / f".out.tmp-{dead}-file").write_text("")
    OutputDir(out, "run")._remove_stale()
    assert (tmp_path / f".out.tmp-{dead}-file").exists()


def test_writable_file_refuses_an_existing_file_unless_replaced(tmp_path):
    """A file (or a dangling link) already at the path is kept unless the command's --force asks
    to replace it; nothing is written either way."""
    old = tmp_path / "old.csv"
    old.write_text("mine")
    link = tmp_path / "link.csv"
    link.symlink_to(tmp_path / "nowhere")
    for p in (old, link):
        assert _refused(files.writable_file, p) == (
            f"{p}: exists; choose another name or add --force to replace it")
        assert files.writable_file(p, replace=True) == p
    assert old.read_text() == "mine"
