"""`tracker bench`: the JSON keys other tools read, and sane figures (no timing is asserted)."""

import json
import re
import shutil

import pytest
from conftest import file_hashes

import tracker.apps.bench as bench
from tracker.apps.bench import HUMAN, _copies, _side_by_side, detector_ms
from tracker.cli import main
from tracker.io.recording import open_recording
from tracker.landmarks.landmark_models import MODELS, RECORDED
from tracker.model import model_from_dict
from tracker.tracking.settings import Settings

KEYS = {
    "stage_fps_with_keypoints",
    "stage_cpu_ms_per_frame_with_keypoints",
    "bound_cores_fps",
    "bound_serial_fps",
    "bound_slowest_stage_fps",
    "ratio_with_keypoints",
    "fps_one_view",
    "fps_all_views",
    "decode_only_fps_all_views",
    "ratio_all_views",
    "core_ms_per_view_iteration",
    "views",
    "frames",
    "detector_ms_per_view",
    "fps_all_views_with_keypoints",
    "stage_ms_per_frame_with_keypoints",
}


def test_bench_json_has_the_documented_keys(tiny_recording, capsys):
    assert main(["bench", str(tiny_recording), "--json", "--repeats", "1"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert KEYS <= set(result)
    assert result["views"] == 2 and result["frames"] == 6
    assert result["fps_all_views"] > 0 and result["decode_only_fps_all_views"] > 0
    assert abs(result["ratio_all_views"] - result["fps_all_views"] / result["decode_only_fps_all_views"]) < 1e-9
    assert set(result["stage_ms_per_frame_all_views"]) >= {"decode", "outline", "measure", "solve", "output"}
    assert result["keypoint_step"] == 4 and result["detector_ms_per_view"] > 0  # the default at the recording's 60 fps
    assert result["landmark_model"] == RECORDED  # the default of the commands on recorded folders, and live's beside it
    assert result["fps_all_views_with_keypoints"] > 0
    assert set(result["stage_ms_per_frame_with_keypoints"]) >= {"outline", "measure", "region", "solve", "output"}
    stages = result["stage_fps_with_keypoints"]
    assert stages["decode_only"] == result["decode_only_fps_all_views"]
    assert set(stages["detect"]) == set(MODELS) and all(fps > 0 for fps in stages["detect"].values())
    alone = {"read": stages["read"], "detect": stages["detect"][RECORDED], "track": stages["track"]}
    assert all(fps > 0 for fps in alone.values())
    assert result["bound_slowest_stage_fps"] == min(alone.values()) == alone[result["slowest_stage"]]
    assert abs(1 / result["bound_serial_fps"] - sum(1 / fps for fps in alone.values())) < 1e-9
    cpu = result["stage_cpu_ms_per_frame_with_keypoints"]
    spent = cpu["read"] + cpu["detect"][RECORDED] + cpu["track"]
    assert set(cpu["detect"]) == set(stages["detect"]) and all(ms > 0 for ms in cpu["detect"].values())
    assert cpu["decode_only"] > 0 and abs(result["bound_cores_fps"] - 1e3 * result["cores"] / spent) < 1e-9
    assert abs(result["ratio_bound_cores"] - cpu["decode_only"] / spent) < 1e-9
    assert result["ratio_with_keypoints"] == result["fps_all_views_with_keypoints"] / stages["decode_only"]
    assert 0 < result["first_landmarks_s"] and result["fps_all_views_with_keypoints_after_first"] > 0


def test_the_detector_is_timed_on_the_images_the_tracker_feeds_it(tiny_recording, monkeypatch):
    """The tracker's readers feed its worker each view reduced as the edge search reduces it; the detector's time is
    taken on those images, not the full-size ones (a 1080x1920 view costs it a third more at full size)."""
    shapes = []

    class Seen:
        def __init__(self, *, landmark_model):
            assert landmark_model == "full"

        def whole(self, image):
            shapes.append(image.shape)

        def close(self):
            pass

    monkeypatch.setattr(bench, "Detector", Seen)
    recording = open_recording(tiny_recording)
    assert detector_ms(recording, Settings().but(images=dict(work_side=120)), landmark_model="full", count=2) >= 0
    assert shapes == [(120, 160, 3)] * 4
    shapes.clear()
    detector_ms(recording, Settings(), landmark_model="full", count=2)
    assert shapes == [(240, 320, 3)] * 4


def test_bench_without_the_cue_times_the_edges_only(tiny_recording, capsys):
    assert main(["bench", str(tiny_recording), "--json", "--repeats", "1", "--keypoints", "off"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["keypoint_step"] == 0 and result["fps_all_views"] > 0
    assert result["fps_all_views_with_keypoints"] != result["fps_all_views_with_keypoints"]  # NaN: not timed
    assert result["stage_ms_per_frame_with_keypoints"] == {}


def test_bench_table_is_printed(tiny_recording, capsys):
    assert main(["bench", str(tiny_recording), "--repeats", "1"]) == 0
    out = capsys.readouterr().out
    rows = re.findall(r"^\| [a-z][^|]* \| ([\d.]+) \| ?([\d.]*) \|$", out, re.M)
    assert len(rows) >= 6 and all(float(ms) >= 0 for ms, _ in rows)  # decode, grey, outline, ..., output
    assert rows[0][1] == "" and all(float(ms) >= 0 for _, ms in rows[1:])  # with the cue: the tracker's stages
    tracking, decoding, ratio = (
        [float(value) for value in re.findall(rf"^\| {row} \| ([\d.]+) \| ([\d.]+) \|$", out, re.M)[0]]
        for row in ("tracking, frames per second", "decode only, frames per second", r"ratio tracking / decode only")
    )
    for fps, decode_fps, shown in zip(tracking, decoding, ratio):  # the fps are printed rounded to whole frames
        assert fps > 0 and decode_fps > 0
        assert (fps - 0.5) / (decode_fps + 0.5) - 0.005 <= shown <= (fps + 0.5) / max(decode_fps - 0.5, 0.5) + 0.005
    assert float(re.findall(r"([\d.]+) ms per view per IRLS iteration", out)[0]) > 0
    detector, with_cue = re.findall(r"the detector takes ([\d.]+) ms per view;.*?, ([\d.]+) frames per second", out)[0]
    assert float(detector) > 0 and float(with_cue) > 0
    stages = {
        name: (float(fps), float(ms) if ms else None, float(ratio))
        for name, fps, ms, ratio in re.findall(
            r"^\| ([a-z][^|]*?) \| ([\d.]+) \| ([\d.]*) \| ([\d.]+) \|$",
            out.split("| with the keypoint cue, all views |")[1],
            re.M,
        )
    }
    floor, decoding, shown = stages["decode only (the floor)"]
    assert (
        shown == 1.0 and decoding > 0 and any(name.startswith(f"detect one frame in 4, {RECORDED}") for name in stages)
    )
    found = {}
    for name in (
        "read",
        f"detect one frame in 4, {RECORDED}",
        "track",
        "bound: read",
        "bound: the slowest",
        "overlapped",
    ):
        fps, ms, ratio = found[name] = next(value for row, value in stages.items() if row.startswith(name))
        assert fps > 0 and abs(ratio - fps / floor) <= 0.005 + 0.05 / floor  # printed to 0.1 frame and 0.01
    cores, spent, share = next(value for row, value in stages.items() if re.match(r"bound: the \d+ cores", row))
    assert abs(spent - sum(found[name][1] for name in ("read", f"detect one frame in 4, {RECORDED}", "track"))) <= 0.16
    assert abs(share - decoding / spent) <= 0.005 + 0.05 * decoding / spent**2 + 0.05 / spent  # by CPU, not fps


def test_bodies_side_by_side_for_the_scaling_table():
    import tomllib

    data = tomllib.loads(HUMAN.read_text())
    model = model_from_dict(_copies(data, 3))
    single = model_from_dict(_copies(data, 1))
    assert model.size == 45 and (model.parent == -1).sum() == 1
    poses = _side_by_side(model, single, 3)
    roots = [poses[model.index(f"pelvis_{k}")][0, 3] for k in range(3)]
    assert roots == [-0.8, 0.0, 0.8]


@pytest.mark.parametrize("missing", ["model.toml", "init.toml"])
def test_bench_on_a_folder_without_model_or_first_pose_is_one_line(tiny_recording, tmp_path, capsys, missing):
    folder = tmp_path / "rec"
    shutil.copytree(tiny_recording, folder)
    (folder / missing).unlink()
    assert main(["bench", str(folder), "--repeats", "1"]) == 2
    errors = [line for line in capsys.readouterr().err.splitlines() if line.startswith("tracker: error:")]
    assert len(errors) == 1 and f"{folder}: no {missing}" in errors[0]
    option = "--model" if missing == "model.toml" else "--init"
    assert f"pass {option}" in errors[0]


def test_bench_refuses_a_first_pose_of_another_frame_than_its_first(tiny_recording, tmp_path, capsys):
    """Its runs start at frame 0: a pose of frame 3 is one line naming the file and the fix, before any timing, the
    files as they were."""
    folder = tmp_path / "rec"
    shutil.copytree(tiny_recording, folder)
    (folder / "init.toml").write_text((folder / "init.toml").read_text().replace("frame = 0\n", "frame = 3\n", 1))
    before = file_hashes(folder)
    assert main(["bench", str(folder), "--repeats", "1"]) == 2
    assert capsys.readouterr().err.splitlines()[-1] == (
        f"tracker: error: {folder / 'init.toml'}: is the pose at frame 3, but tracker bench starts at frame 0; pass "
        f"--init with a pose at frame 0 (tracker init {folder} --out FILE writes one)"
    )
    assert file_hashes(folder) == before


def test_bench_takes_the_model_and_first_pose_from_elsewhere(tiny_recording, tmp_path, capsys):
    """A folder with only its calibration and videos (a lab's recording): --model and --init give the rest."""
    folder = tmp_path / "rec"
    shutil.copytree(tiny_recording, folder)
    for name in ("model.toml", "init.toml"):
        shutil.move(folder / name, tmp_path / name)
    args = ["bench", str(folder), "--model", str(tmp_path / "model.toml"), "--init", str(tmp_path / "init.toml")]
    assert main([*args, "--json", "--repeats", "1", "--keypoints", "off"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["frames"] == 6 and result["fps_all_views"] > 0
    assert main(["bench", str(folder), "--model", str(tmp_path / "nowhere.toml"), "--init", str(tmp_path)]) == 2
    assert "nowhere.toml" in capsys.readouterr().err


def test_a_long_run_reads_the_recording_in_a_loop_and_reports_memory(tiny_recording, capsys, monkeypatch):
    """30 frames of a 6-frame recording: five passes, every frame written, memory read before, after the
    settled frame and at the end (Linux reports it; the CI machines are Linux)."""
    from tracker.apps import bench

    monkeypatch.setattr(bench, "SETTLED", 12)
    assert main(["bench", str(tiny_recording), "--long", "30", "--keypoints", "off", "--json", "--quiet"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["frames"] == 30 and result["frames_written"] == 30 and result["settled_frame"] == 12
    memory = [result[key] for key in ("resident_mb_start", "resident_mb_settled", "resident_mb_end")]
    assert all(50 < value < 5000 for value in memory)
    assert result["resident_mb_growth_after_settled"] == result["resident_mb_end"] - result["resident_mb_settled"]
    assert main(["bench", str(tiny_recording), "--long", "8", "--keypoints", "off", "--quiet"]) == 0
    assert "poses.npz holds 8" in capsys.readouterr().out
