"""phi_rs.generate_dataset against `phi dataset generate`: the same files byte for byte, the
progress callback, an exception in it stopping the run, and bad arguments."""

import pytest

import phi_rs


def files(folder):
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.suffix == ".npz"
    }


def test_generate_dataset_writes_what_the_command_line_writes(tmp_path, phi):
    calls = []
    summary = phi_rs.generate_dataset(
        tmp_path / "py", split="test", trajectories=2, steps=8, threads=1,
        progress=lambda done, total: calls.append((done, total)),
    )
    assert summary["written"] == 2 and summary["skipped"] == 0
    assert calls == [(1, 2), (2, 2)]
    phi("dataset", "generate", "--out", str(tmp_path / "cli"), "--split", "test",
        "--trajectories", "2", "--steps", "8", "--threads", "1")
    ours, theirs = files(tmp_path / "py"), files(tmp_path / "cli")
    assert len(ours) == 2 and ours == theirs
    again = phi_rs.generate_dataset(tmp_path / "py", split="test", trajectories=2, steps=8)
    assert again["written"] == 0 and again["skipped"] == 2


def test_an_exception_in_the_callback_stops_the_run(tmp_path):
    def stop(done, total):
        raise RuntimeError(f"stop at {done} of {total}")

    with pytest.raises(RuntimeError, match="stop at 1 of 3"):
        phi_rs.generate_dataset(tmp_path, split="test", trajectories=3, steps=8, threads=1,
                                progress=stop)
    kept = files(tmp_path)
    assert 1 <= len(kept) < 3


def test_bad_arguments_raise_dataset_errors(tmp_path):
    with pytest.raises(phi_rs.DatasetError, match="'exam' is not"):
        phi_rs.generate_dataset(tmp_path, split="exam")
    with pytest.raises(phi_rs.DatasetError, match="unknown variant"):
        phi_rs.generate_dataset(tmp_path, variant="sponge")
    with pytest.raises(phi_rs.DatasetError, match=r"\(2, 2\)"):
        phi_rs.generate_dataset(tmp_path, shard=(2, 2))
    foreign = tmp_path / "foreign"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("mine")
    with pytest.raises(phi_rs.DatasetError):
        phi_rs.generate_dataset(foreign, split="test", trajectories=1, steps=8, force=True)
    assert (foreign / "notes.txt").read_text() == "mine"
