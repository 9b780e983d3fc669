"""End-to-end benchmark of the live node: 1280x1024 mono8 frames, default settings, CPU.

Phase 1 (lockstep): publish a frame, wait for its ~/frame status -> throughput (frames/s) and latency
(image stamp -> status received, ms p50/p95) without queueing.
Phase 2 (30 Hz camera): a publisher process sends frames + metadata at 30 Hz -> evaluated frames/s, the
/diagnostics (period summary) rate, frames dropped by the node (busy worker), latency p50/p95.

Usage: .venv/bin/python bench/bench_node.py [--frames 40] [--seconds 15] [--rate 30] [--shm-segment-mb 16]
                                           [--drift] [--scene smooth|photo] [--patch-size 64|128] [--json out.json]
``--drift``: new metadata every frame, as a live driver reports it: the temperature rises by 0.013 degC
per frame, auto-exposure moves the exposure +-20 % and auto-gain the gain +-1 dB (the physics tables are
then interpolated, never recomputed per metadata set). ``--scene photo``: a still textured scene, on which the
temporal measurement runs every frame (also while the metadata drift); the default smooth scene never holds.
Prints figures; asserts nothing. Fast DDS's default shared-memory segment (512 KiB) is smaller than a
1280x1024 image, so such samples go over UDP fragments that a best-effort (sensor-data) subscription
loses under CPU load; ``--shm-segment-mb`` writes a Fast DDS profile with a larger segment and uses it
for both processes (how to deploy the node next to a camera driver on the same machine).
"""
from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import time
from pathlib import Path

import numpy as np

WIDTH, HEIGHT = 1280, 1024
PROFILE = "icx285"
DYNAMIC = {"gain_db": 18.0, "exposure_time_s": 0.01, "sensor_temperature_c": 40.0}
IMAGE_TOPIC, META_TOPIC = "/bench_camera/image_raw", "/bench_camera/metadata"


def make_frames(n: int, seed: int = 0, scene: str = "smooth") -> list[np.ndarray]:
    """n noisy mono8 frames of a scene (the simulator's joint mode): ``smooth`` (sinusoids: phase correlation cannot
    tell the camera still, so the node never enters a static hold) or ``photo`` (scikit-image's astronaut: a still,
    textured scene, the temporal measurement runs every frame)."""
    from noise_monitor.physics import NoiseModel, load_profile

    rng = np.random.default_rng(seed)
    if scene == "photo":
        import cv2
        from skimage import data

        gray = cv2.cvtColor(data.astronaut(), cv2.COLOR_RGB2GRAY)
        clean = 20.0 + 0.8 * cv2.resize(gray, (WIDTH, HEIGHT), interpolation=cv2.INTER_CUBIC).astype(np.float32)
    else:
        y, x = np.mgrid[0:HEIGHT, 0:WIDTH].astype(np.float32)
        clean = 120 + 60 * np.sin(2 * np.pi * x / WIDTH * 3) * np.cos(2 * np.pi * y / HEIGHT * 2) + 20 * x / WIDTH
    meta = load_profile(PROFILE).metadata(**DYNAMIC)
    model = NoiseModel()
    return [np.clip(np.rint(model.simulate(clean, meta, rng)[0]), 0, 255).astype(np.uint8) for _ in range(n)]


def dynamic(i: int, drift: bool) -> dict[str, float]:
    """Metadata of frame i: fixed, or drifting every frame (temperature ramp, auto-exposure, auto-gain)."""
    if not drift:
        return DYNAMIC
    return {"gain_db": DYNAMIC["gain_db"] + np.sin(i / 40.0), "sensor_temperature_c": DYNAMIC["sensor_temperature_c"] + 0.013 * i,
            "exposure_time_s": DYNAMIC["exposure_time_s"] * (1.0 + 0.2 * np.sin(i / 15.0))}


def messages(img: np.ndarray, stamp_ns: int, values: dict[str, float] = DYNAMIC):
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from sensor_msgs.msg import Image

    stamp = Time(sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    meta = DiagnosticArray()
    meta.header.stamp = stamp
    meta.status = [DiagnosticStatus(name="bench camera", values=[KeyValue(key=k, value=repr(float(v))) for k, v in values.items()])]
    image = Image(height=img.shape[0], width=img.shape[1], encoding="mono8", step=img.shape[1], data=img.tobytes())
    image.header.stamp = stamp
    return image, meta


def publisher_process(rate_hz: float, seconds: float, ready: mp.Event, go: mp.Event, sent: mp.Value,
                      drift: bool = False, scene: str = "smooth") -> None:
    """A separate process playing a camera at rate_hz (own GIL, like a real driver)."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    frames = make_frames(6, seed=1, scene=scene)
    rclpy.init()
    node = rclpy.create_node("bench_camera")
    pub_img = node.create_publisher(Image, IMAGE_TOPIC, qos_profile_sensor_data)
    pub_meta = node.create_publisher(DiagnosticArray, META_TOPIC, 10)
    ready.set()
    go.wait()
    period = 1.0 / rate_hz
    start = time.monotonic()
    i = 0
    while time.monotonic() - start < seconds:
        image, meta = messages(frames[i % len(frames)], time.time_ns(), dynamic(i, drift))
        pub_meta.publish(meta)
        pub_img.publish(image)
        i += 1
        time.sleep(max(0.0, start + i * period - time.monotonic()))
    sent.value = i
    node.destroy_node()
    rclpy.shutdown()


SHM_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <transport_descriptors>
    <transport_descriptor><transport_id>shm_large</transport_id><type>SHM</type>
      <segment_size>{size}</segment_size></transport_descriptor>
  </transport_descriptors>
  <participant profile_name="large_images" is_default_profile="true">
    <rtps><userTransports><transport_id>shm_large</transport_id></userTransports>
      <useBuiltinTransports>false</useBuiltinTransports></rtps>
  </participant>
</profiles>
"""


def write_shm_profile(segment_mb: int) -> str:
    """A Fast DDS profile (temporary file) with a shared-memory transport of segment_mb MiB segments."""
    import tempfile

    fd, path = tempfile.mkstemp(prefix="fastdds_shm_", suffix=".xml")
    with os.fdopen(fd, "w") as fh:
        fh.write(SHM_PROFILE.format(size=segment_mb * 1024 * 1024))
    return path


def pct(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=40, help="lockstep frames")
    ap.add_argument("--seconds", type=float, default=15.0, help="duration of the 30 Hz phase")
    ap.add_argument("--rate", type=float, default=30.0, help="publisher rate of phase 2 (Hz)")
    ap.add_argument("--weights", help="estimator checkpoint to benchmark instead of the bundled full_meta")
    ap.add_argument("--patch-size", type=int, default=None, help="the node's patch_size parameter (default: node.yaml)")
    ap.add_argument("--shm-segment-mb", type=int, default=None,
                    help="Fast DDS shared-memory segment size (0 = Fast DDS default); default: run both 0 and 16")
    ap.add_argument("--drift", action="store_true", help="new metadata every frame (temperature, exposure, gain)")
    ap.add_argument("--scene", choices=("smooth", "photo"), default="smooth",
                    help="smooth: no static hold is seen; photo: a still textured scene, the temporal measurement runs")
    ap.add_argument("--json", help="write the figures to this JSON file")
    args = ap.parse_args()
    if args.shm_segment_mb is None:
        compare_transports(args)
        return
    run_once(args)


def compare_transports(args: argparse.Namespace) -> None:
    """Run the benchmark once with Fast DDS defaults and once with 16 MiB shared-memory segments."""
    import subprocess
    import sys
    import tempfile

    both = {}
    for mb in (0, 16):
        with tempfile.NamedTemporaryFile(suffix=".json") as out:
            cmd = [sys.executable, __file__, "--frames", str(args.frames), "--seconds", str(args.seconds),
                   "--rate", str(args.rate), "--shm-segment-mb", str(mb), "--json", out.name]
            if args.weights:
                cmd += ["--weights", args.weights]
            if args.drift:
                cmd.append("--drift")
            cmd += ["--scene", args.scene]
            if args.patch_size is not None:
                cmd += ["--patch-size", str(args.patch_size)]
            print(f"--- transport: {'Fast DDS default' if mb == 0 else f'shared memory, {mb} MiB segments'}", flush=True)
            subprocess.run(cmd, check=True)
            both["fastdds_default" if mb == 0 else f"shm_{mb}mb"] = json.loads(Path(out.name).read_text())
    if args.json:
        Path(args.json).write_text(json.dumps(both, indent=2))


def run_once(args: argparse.Namespace) -> None:
    """One benchmark run (lockstep + live phase) with the transport chosen by args.shm_segment_mb."""
    os.environ.setdefault("ROS_DOMAIN_ID", str(150 + os.getpid() % 50))
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    if args.shm_segment_mb:
        os.environ["FASTRTPS_DEFAULT_PROFILES_FILE"] = write_shm_profile(args.shm_segment_mb)

    import rclpy
    import torch
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.parameter import Parameter
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Image

    from msg_adapters import reports_from_msg
    from noise_monitor.monitor.config import default_params_path
    from noise_monitor.node import node_class

    ctx = rclpy.Context()
    rclpy.init(args=["bench", "--ros-args", "--params-file", str(default_params_path())], context=ctx)
    overrides = [Parameter("image_topic", value=IMAGE_TOPIC), Parameter("metadata_topic", value=META_TOPIC),
                 Parameter("camera_info_topic", value=""), Parameter("profile", value=PROFILE),
                 Parameter("device", value="cpu")]
    if args.patch_size is not None:
        overrides.append(Parameter("patch_size", value=args.patch_size))
    t0 = time.perf_counter()
    estimator = None
    if args.weights:
        from noise_monitor.estimator import load

        estimator = load("full_meta", device="cpu", weights=args.weights)
    node = node_class()(parameter_overrides=overrides, context=ctx, estimator=estimator)
    startup_s = time.perf_counter() - t0
    probe = rclpy.create_node("bench_probe", context=ctx)
    received: list[tuple[int, int, dict]] = []  # (receive ns, image stamp ns, values)

    summaries: list[int] = []  # /diagnostics period summaries (receive ns)

    def on_frame(msg) -> None:  # one status per frame on ~/frame; evaluated ones carry the numbers
        report = reports_from_msg(msg)[0]
        if "sigma_rn" in report.values:
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
            received.append((time.time_ns(), stamp, report.values))

    probe.create_subscription(DiagnosticArray, f"{node.get_fully_qualified_name()}/frame", on_frame, 100)
    probe.create_subscription(DiagnosticArray, "/diagnostics", lambda _: summaries.append(time.time_ns()), 100)
    pub_img = probe.create_publisher(Image, IMAGE_TOPIC, qos_profile_sensor_data)
    pub_meta = probe.create_publisher(DiagnosticArray, META_TOPIC, 10)
    ex = SingleThreadedExecutor(context=ctx)
    ex.add_node(node)
    ex.add_node(probe)

    def spin_until(pred, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.01)
            if pred():
                return True
        return False

    spin_until(lambda: pub_img.get_subscription_count() > 0, 10.0)
    frames = make_frames(6, scene=args.scene)
    # --- phase 1: lockstep ---
    lat, t_start = [], time.perf_counter()
    for i in range(args.frames + 3):
        if i == 3:  # warm-up: first inference and table building
            lat, t_start = [], time.perf_counter()
        n0 = len(received)
        image, meta = messages(frames[i % len(frames)], time.time_ns(), dynamic(i, args.drift))
        pub_meta.publish(meta)
        pub_img.publish(image)
        if not spin_until(lambda: len(received) > n0, 30.0):
            raise SystemExit("no diagnostics within 30 s: is the estimator loadable?")
        lat.append((received[-1][0] - received[-1][1]) / 1e6)
    lock_fps = args.frames / (time.perf_counter() - t_start)
    proc_ms = [float(v["processing_ms"]) for _, _, v in received[-args.frames:]]
    # --- phase 2: a camera at args.rate Hz in another process ---
    c0 = dict(node.monitor.counters)
    received.clear()
    spawn = mp.get_context("spawn")
    ready, go, sent = spawn.Event(), spawn.Event(), spawn.Value("i", 0)
    proc = spawn.Process(target=publisher_process, args=(args.rate, args.seconds, ready, go, sent, args.drift,
                                                                args.scene))
    proc.start()
    ready.wait(60)
    spin_until(lambda: False, 2.0)  # discovery
    go.set()
    summaries.clear()  # /diagnostics counted from the start of the camera's frames
    t_start = time.perf_counter()
    spin_until(lambda: not proc.is_alive(), args.seconds + 30)
    spin_until(lambda: False, 1.0)  # let the last frame finish
    elapsed = time.perf_counter() - t_start
    proc.join()
    live_lat = [(r - s) / 1e6 for r, s, _ in received]
    figures = {
        "image": f"{WIDTH}x{HEIGHT} mono8", "profile": PROFILE, "torch_threads": torch.get_num_threads(),
        "estimator": node.monitor.estimator.name, "patch_size": node.monitor.patch_size,
        "patches_per_frame": node.monitor.config.patches_per_frame, "node_startup_s": round(startup_s, 2),
        "lockstep_frames_per_s": round(lock_fps, 2),
        "lockstep_latency_ms_p50": round(pct(lat, 50), 1), "lockstep_latency_ms_p95": round(pct(lat, 95), 1),
        "processing_ms_p50": round(pct(proc_ms, 50), 1), "processing_ms_p95": round(pct(proc_ms, 95), 1),
        "publisher_hz": args.rate, "published": int(sent.value),
        "evaluated_per_s": round(len(received) / elapsed, 2),
        "diagnostics_per_s": round(len(summaries) / elapsed, 2),
        "frames_reaching_node": sum(node.monitor.counters[k] - c0[k] for k in ("frames_received", "frames_dropped")),
        "frames_lost_before_node": node.monitor.counters["frames_lost"] - c0["frames_lost"],
        "frames_evaluated": len(received), "frames_dropped": node.monitor.counters["frames_dropped"] - c0["frames_dropped"],
        "live_latency_ms_p50": round(pct(live_lat, 50), 1), "live_latency_ms_p95": round(pct(live_lat, 95), 1),
        "metadata": "new every frame (drift)" if args.drift else "fixed",
        "scene": args.scene,
        "cpu_cores": os.cpu_count(), "shm_segment_mb": args.shm_segment_mb or "Fast DDS default",
    }
    width = max(map(len, figures))
    for k, v in figures.items():
        print(f"{k:<{width}}  {v}")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(figures, fh, indent=2)
    ex.shutdown()
    node.destroy_node()
    probe.destroy_node()
    ctx.try_shutdown()


if __name__ == "__main__":
    main()
