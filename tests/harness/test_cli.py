import os

from harness.cli.main import main


def test_scenes_lists_the_shipped_scenes(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    assert "earth-specular" in out and "sparse-colored" in out and "probe-envmap" in out


def test_generate_with_overrides_and_refusal_to_overwrite(tmp_path, capsys):
    out = tmp_path / "ds"
    args = ["generate", "sparse-colored", "-o", str(out), "--profile", "tiny", "--views", "3",
            "--test-views", "1", "--resolution", "24"]
    assert main(args) == 0
    assert sorted(os.listdir(out / "images")) == ["test_000.exr", "train_000.exr", "train_001.exr", "train_002.exr"]
    assert main(args) == 2
    assert "--overwrite" in capsys.readouterr().err
    assert main(args + ["--overwrite"]) == 0


def test_user_errors_exit_2_with_a_message(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "x"\n[cameras]\nwidht = 3\n')
    assert main(["generate", str(bad), "-o", str(tmp_path / "o")]) == 2
    assert "cameras.widht" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
