"""`noise-monitor scenes`: the static holds of a recording as clean scene images, for `evaluate --images`."""
from __future__ import annotations

import json
from itertools import groupby

import cv2
import numpy as np
import torch

from noise_monitor.bag.simulate import load_truth, simulate_bag
from noise_monitor.cli import main as cli_main

torch.set_num_threads(1)


class KeepClean:
    """Frame hook that records each clean frame, leaving the noisy one as simulated."""

    truth: dict = {}

    def __init__(self) -> None:
        self.frames: list[np.ndarray] = []

    def __call__(self, index, clean, noisy, meta):
        self.frames.append(clean.copy())
        return noisy


def test_scenes_are_the_holds_temporal_means(tmp_path, capsys) -> None:
    """On a field-like campaign (holds with the temperature drifting ~1 degC per frame, pans between them) every
    hold of the truth is found with its exact frames, and each PNG is the mean of the hold's clean frames to within
    the temporal noise left in it and the 8-bit rounding; the scenes feed `evaluate --images`."""
    hook = KeepClean()
    bag = simulate_bag(tmp_path / "c.mcap", "ev76c661", "campaign_heldout", frames=60, width=160, height=128, seed=5,
                       frame_hook=hook)
    holds = [(k, [f["index"] for f in g]) for k, g in groupby(load_truth(bag)["frames"], key=lambda f: f["hold"])]
    expected = [(idx[0], idx[-1]) for k, idx in holds if k >= 0 and len(idx) >= 4]
    out = tmp_path / "scenes"
    assert cli_main(["scenes", str(bag), "--out", str(out), "--min-frames", "4", "--json", str(tmp_path / "s.json")]) == 0
    scenes = json.loads((tmp_path / "s.json").read_text())
    assert [(s["first_index"], s["last_index"]) for s in scenes] == expected and len(expected) >= 3
    for s in scenes:
        img = cv2.imread(str(out / s["file"]), cv2.IMREAD_UNCHANGED).astype(np.float64)
        clean = np.mean(hook.frames[s["first_index"]:s["last_index"] + 1], axis=0)
        rms = float(np.sqrt(np.mean((img - clean) ** 2)))
        # the noise left, said (the temporal noise's RMS over sqrt(N) and the PNG's rounding; until 2026-12-04 the
        # median over pixels without the rounding, below what is left)
        assert 0.9 * s["noise_left_dn"] < rms < 1.1 * s["noise_left_dn"], (s, rms)
    printed = capsys.readouterr().out
    assert f"noise-monitor evaluate --images {out} " in printed  # a path without spaces as it is
    assert cli_main(["scenes", str(bag), "--out", str(out), "--min-frames", "40"]) == 2
    assert "no static hold of 40" in capsys.readouterr().err
    assert cli_main(["evaluate", "--images", str(out), "--image-downsample", "1", "--patches", "20", "--parts", "a",
                     "--variants", "full_meta", "--no-peers", "--cache", str(tmp_path / "cache"),
                     "--json", str(tmp_path / "e.json")]) == 0
    floors = [i["own_noise_floor_dn"] for i in json.loads((tmp_path / "e.json").read_text())["images"]]
    assert len(floors) == len(scenes)


def test_scenes_name_the_unusable_frames_and_quote_the_next_command(tmp_path, capsys) -> None:
    """A recording whose frames all lack metadata: the error names why (until 2026-12-04 only "no static hold of 8
    usable frames"); the command printed for the scenes quotes a folder with a space (it was pasted as two paths)."""
    from noise_monitor.bag.reader import open_bag
    from noise_monitor.bag.writer import BagWriter

    bag = simulate_bag(tmp_path / "c.mcap", "ev76c661", "static", frames=12, width=96, height=64, seed=2)
    images_only = tmp_path / "images_only.mcap"
    with open_bag(bag) as reader, BagWriter(images_only) as w:
        for topic, log_time, msg in reader.messages([reader.image_topic]):
            w.write(topic, msg, log_time)
    assert cli_main(["scenes", str(images_only), "--out", str(tmp_path / "none"), "--min-frames", "4"]) == 2
    assert ("no static hold of 4 usable frames or more (unusable: 12 frame(s): metadata missing: "
            in capsys.readouterr().err)
    out = tmp_path / "my scenes"
    assert cli_main(["scenes", str(bag), "--out", str(out), "--min-frames", "4"]) == 0
    assert f"noise-monitor evaluate --images '{out}' --image-downsample 1" in capsys.readouterr().out
