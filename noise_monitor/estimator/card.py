"""Model cards: ``weights/<name>.md`` from the training summary and the held-out evaluation."""
from __future__ import annotations

import json
from pathlib import Path

import torch

from .evaluate import HELDOUT_SETS
from .images import JPEG_QUALITY, PHOTO_DOWNSCALE
from .networks import count_parameters, network_from_checkpoint

ROWS = ("pn", "dcsn", "rn", "sigma_image", "xi")


def write_card(name: str, weights_dir: Path, runs: dict[str, dict], command: str) -> Path:
    """Write ``<name>.md`` next to ``<name>.pt``: training facts (``<name>.train.json`` if present) and one
    held-out benchmark table per evaluated patch size (``runs``: label -> results of ``evaluate``)."""
    ck = torch.load(weights_dir / f"{name}.pt", map_location="cpu", weights_only=True)
    train_json = weights_dir / f"{name}.train.json"
    train = json.loads(train_json.read_text()) if train_json.is_file() else {}
    net = network_from_checkpoint(ck)
    lines = [f"# Model card: `{name}`", "",
             f"- Network: {type(net).__name__} {json.dumps(ck['config'])}, {count_parameters(net):,} parameters",
             f"- Weights: `{name}.pt` ({(weights_dir / f'{name}.pt').stat().st_size / 1024:.0f} KiB), "
             f"{ck['step'] + ck.get('prior_steps', 0)} steps, {(ck['elapsed_s'] + ck.get('prior_elapsed_s', 0.0)) / 60:.1f} min "
             "training wall time in total on the shared 2-core CPU" + (" (fine-tuned from an earlier run, see command)" if ck.get("prior_steps") else "")]
    for stage in _stages(train)[:-1]:
        if stage.get("init_note"):
            lines += [f"- Before the next stage: {stage['init_note']}"]
        lines += [f"- Earlier stage (its weights are this run's `--init`): `{stage.get('command', '?')}` "
                  f"({stage['patches']} patches, data {stage['data_seconds'] / 60:.1f} min, training "
                  f"{stage['train_seconds'] / 60:.1f} min)"]
    if train.get("init_note"):
        lines += [f"- Between the earlier stages and this run: {train['init_note']}"]
    if train:
        lines += [f"- Training command: `{train.get('command', '?')}`",
                  f"- Data: {train['patches']} simulated patches of {train['patch_size']}x{train['patch_size']} px "
                  f"(scikit-image bundled photos{_variants(train)} + dead leaves{_procedural(train)}, sequential simulator, xi scheme; data seed "
                  f"{train.get('data_seed', '?')}" + (f", corruption scheme {json.dumps(train['scheme'])}" if "scheme" in train else "")
                  + ")" + (" (pre-generated dataset file; the same command without --data regenerates it identically "
                     "from the data seed)" if train.get("data_reused", train["data_seconds"] < 60) else
                     f", generated in {train['data_seconds'] / 60:.1f} min"),
                  f"- Training settings (as given; the network's inputs are its config above, those of an --init "
                  f"kept): {json.dumps(train['settings'])}"]
    if ck["config"].get("confidence"):
        from .inference import MEASURABLE_ERROR_DN, MEASURABLE_RELATIVE_ERROR

        evidence = " and the patch's texture evidence (`evidence.py`)" if ck["config"].get("evidence") else ""
        lines += [f"- Confidence head {ck['config']['confidence']} (predicted error of sigma_image from the measurement's "
                  f"features{evidence}): trained alone with the measurement frozen (`--confidence`, Gaussian NLL of the log "
                  f"residual); a patch whose predicted error exceeds {MEASURABLE_ERROR_DN} DN or "
                  f"{MEASURABLE_RELATIVE_ERROR:.0%} of sigma_image is declined as not measurable"]
    if train.get("selection_note"):
        lines += [f"- Chosen on the tuning sets (the held-out sets below were run once, with the design fixed): "
                  f"{train['selection_note']}"]
    lines += ["", f"Benchmark command: `{command}`"]
    for label, results in runs.items():
        lines += _benchmark(name, label, results)
    path = weights_dir / f"{name}.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def _variants(train: dict) -> str:
    n = train.get("photo_variants", 0)
    im = train.get("imagery") or {}
    if n and im and (tuple(im.get("photo_scales", PHOTO_DOWNSCALE)) != PHOTO_DOWNSCALE or im.get("photo_native")
                     or im.get("photo_rotate")):
        lo, hi = im.get("photo_scales", PHOTO_DOWNSCALE)
        return (f" (each {n}x: {im.get('photo_rotate', 0):.0%} rotated by an arbitrary angle, {im.get('photo_native', 0):.0%} "
                f"at native resolution, else a random {lo:g}-{hi:g}x downscale; random gamma)")
    return f" (each {n}x at a random {PHOTO_DOWNSCALE[0]}-{PHOTO_DOWNSCALE[1]:g}x downscale and gamma)" if n else ""


def _procedural(train: dict) -> str:
    n = train.get("procedural", 0)
    im = train.get("imagery") or {}
    text = f" + {n} procedural images of pixel-scale structure (hillshades, gratings, fabric, halftone, text)" if n else ""
    if im.get("manmade"):
        text += f" + {im['manmade']} man-made procedural scenes (dead leaves of polygons, periodic bars)"
    if im.get("grain"):
        text += f" + {im['grain']} grainy procedural pictures (near-white grain as scene content)"
    if im.get("charts"):
        text += f" + {im['charts']} test charts (tiles over the whole intensity range)"
    if im.get("gratings"):
        text += f" + {im['gratings']} plain gratings (pixel-scale sine gratings over the whole image)"
    if im.get("jpeg"):
        text += f"; {im['jpeg']:.0%} of the source images JPEG-compressed (quality {JPEG_QUALITY[0]}-{JPEG_QUALITY[1]})"
    return text


def _stages(train: dict) -> list[dict]:
    """Training summaries from the first stage to the last (``init_from`` chains fine-tuning runs)."""
    return (_stages(train["init_from"]) if "init_from" in train else []) + ([train] if train else [])


def rms_cell(s: dict | None) -> str:
    """An RMS (DN), with its 95 % interval when the scores carry one."""
    if s is None:
        return "-"
    ci, by_image = s.get("rms_ci95"), s.get("rms_ci95_images")
    return (f"{s['rms']:.3f}" + (f" [{ci[0]:.3f}, {ci[1]:.3f}]" if ci else "")
            + (f" (images {by_image[0]:.3f}-{by_image[1]:.3f})" if by_image else ""))


def rate_cell(rate: float, ci: list[float] | None, by_image: list[float] | None = None) -> str:
    """A rate in percent, with its 95 % interval when the scores carry one (and that over the source images)."""
    return (f"{100 * rate:.1f} %" + (f" [{100 * ci[0]:.1f}, {100 * ci[1]:.1f}]" if ci else "")
            + (f" (images {100 * by_image[0]:.1f}-{100 * by_image[1]:.1f})" if by_image else ""))


def declined_alarms(d: dict) -> str:
    if "false_alarm_rate" in d:
        return f"false {rate_cell(d['false_alarm_rate'], d.get('false_alarm_ci95'), d.get('false_alarm_ci95_images'))}"
    if d.get("hit_rate") is None:
        return "-"
    acc = d.get("hit_rate_accepted")
    hits = rate_cell(d["hit_rate"], d.get("hit_ci95"), d.get("hit_ci95_images"))
    return f"hits {hits} / {'-' if acc is None else f'{100 * acc:.1f} %'}"


def _benchmark(name: str, label: str, results: dict) -> list[str]:
    size = results["patch_size"].get(name)
    title = f"{size}x{size} patches" + (" (native)" if label.startswith("native") else "")
    heldout_set = results.get("heldout", "benchmark")
    heading = "Held-out benchmark" if heldout_set == "benchmark" else f"Held-out set `{heldout_set}`"
    lines = ["", f"## {heading}, {title}", "",
             f"{results['patches_per_part']} patches per part, {HELDOUT_SETS[heldout_set].description}, unseen seeds. "
             "RMS (Bias / Std) in DN; alarms: false alarms |xi| > 1 DN on (a), hits on (b)/(c) where |xi_true| > 2 DN.", "",
             "| part | " + " | ".join(ROWS) + " | alarms |", "|---" * (len(ROWS) + 2) + "|"]
    for part, rows in results["parts"].items():
        r = rows.get(name)
        if r is None:
            continue
        cells = [f"{r[k]['rms']:.3f} ({r[k]['bias']:.3f} / {r[k]['std']:.3f})" if k in r else "-" for k in ROWS]
        rate = r.get("false_alarm_rate", r.get("hit_rate"))
        alarm = "-" if rate is None else f"{'false' if 'false_alarm_rate' in r else 'hits'} {100 * rate:.1f} %"
        lines.append(f"| ({part}) | " + " | ".join(cells) + f" | {alarm} |")
    declined = {part: rows[name]["declined"] for part, rows in results["parts"].items() if "declined" in rows.get(name, {})}
    if declined:
        lines += ["", "Unmeasurable patches declined (confidence head; a declined patch is never a false alarm nor a hit):", "",
                  "| part | coverage | xi RMS on accepted | alarms (all candidates / accepted) | with clear decisions: "
                  "coverage, alarms |", "|---|---|---|---|---|"]
        for part, d in declined.items():
            c = results["parts"][part][name].get("decided")
            clear = "-" if c is None else f"{100 * c['coverage']:.1f} %, {declined_alarms(c)}"
            lines.append(f"| ({part}) | {100 * d['coverage']:.1f} % | {rms_cell(d['xi'])} | {declined_alarms(d)} | {clear} |")
    sens = results.get("sensitivity_full_meta")
    if sens and name == "full_meta":
        lines += ["", f"Metadata sensitivity sweep (paper's protocol, sequential model reference): max |estimator - model| = "
                  f"{sens['max_abs_diff_dn']} DN, {sens['flagged_cells']} cells off by > 1 DN."]
    if name in results.get("ms_per_patch", {}):
        lines += ["", f"Evaluation throughput: {results['ms_per_patch'][name]} ms/patch (batch 64, CPU, incl. building the physics "
                  "tables of a new metadata set every 8 patches; a camera frame shares one set: see bench/bench_estimator.py)."]
    return lines
