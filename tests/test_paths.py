"""Where the project and the shared data are found."""

from __future__ import annotations

from pathlib import Path

from pimann.core.paths import PACKAGE_CHECKOUT, SHARED_ENV, project_root, shared_dir


def test_project_root_is_found_from_the_working_folder(tmp_path):
    (tmp_path / "params.yaml").write_text("profile: quick\n")
    (tmp_path / "dvc.yaml").write_text("stages: {}\n")
    (tmp_path / "stages").mkdir()
    assert project_root(tmp_path / "stages") == tmp_path.resolve()


def test_project_root_falls_back_to_the_package_checkout(tmp_path):
    assert project_root(tmp_path) == PACKAGE_CHECKOUT


def test_shared_dir_follows_the_setting(monkeypatch, tmp_path):
    monkeypatch.setenv(SHARED_ENV, str(tmp_path))
    assert shared_dir() == tmp_path.resolve()
    monkeypatch.delenv(SHARED_ENV)
    assert shared_dir().name == "shared" and (shared_dir() / "robots").is_dir()
    assert shared_dir() == (project_root().parent / "shared").resolve()


def test_repo_relative_paths(tmp_path):
    from pimann.core.paths import REPO_ROOT, repo_relative

    assert repo_relative(REPO_ROOT / "models" / "w10" / "0") == "models/w10/0"
    assert repo_relative(tmp_path / "x.h5") == str((tmp_path / "x.h5").resolve())


def test_repo_relative_keeps_a_linked_folder_relative_and_repo_path_reads_it_back(tmp_path):
    """A checkout's data/ may be a link to elsewhere: recorded by its spelling, the path is
    the same in every checkout; repo_path opens it against REPO_ROOT."""
    import tempfile

    from pimann.core.paths import REPO_ROOT, repo_path, repo_relative

    (tmp_path / "full.h5").write_text("x")
    with tempfile.TemporaryDirectory(dir=REPO_ROOT) as inside:
        link = Path(inside) / "data"
        link.symlink_to(tmp_path)
        recorded = repo_relative(link / "full.h5")
        assert recorded == f"{Path(inside).name}/data/full.h5"
        assert repo_path(recorded).read_text() == "x"
    assert repo_path("/abs/x.h5") == Path("/abs/x.h5")
    assert repo_path("models/w10") == REPO_ROOT / "models" / "w10"
