"""`libfx run --sidecar FILE` names the scene sidecar; `--camera FILE`, its former name,
stays an alias so saved scripts keep working: both give the same bytes."""
import json

from conftest import EXIT_OK, make_frame, write_recipe


def test_sidecar_and_its_camera_alias_give_the_same_output(run, tmp_path):
    src = make_frame(tmp_path / "in.exr")
    side = tmp_path / "scene.json"
    side.write_text(json.dumps({
        "world_to_camera": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -5], [0, 0, 0, 1]],
        "projection": [[1.5, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]],
        "clip_start": 0.1, "clip_end": 100.0, "frame": 3, "fps": 24}))
    recipe = write_recipe(tmp_path / "r.json", [{"effect": "pixelate"}])
    outs = []
    for opt in ("--sidecar", "--camera"):
        out = tmp_path / ("out%s.exr" % opt)
        r = run("run", "--stack", recipe, opt, side, src, "-o", out)
        assert r.returncode == EXIT_OK, r.stderr
        assert json.loads(run("info", "--compact", out).stdout)["camera"] is True
        outs.append(out.read_bytes())
    assert outs[0] == outs[1]


def test_help_names_sidecar_and_the_alias(run):
    text = run("run", "--help").stdout
    assert "--sidecar FILE" in text and "--camera" in text
