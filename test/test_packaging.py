"""The package as users install it: a wheel built from this tree into a fresh venv gives a working CLI, and a colcon
workspace holding it installs what `ros2 run` and `ros2 launch` look up."""
from __future__ import annotations

import ast
import importlib.util
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
import venv
from pathlib import Path
from xml.etree import ElementTree

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _run(cmd: list[str], cwd: Path, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=900, **kw)


def test_package_xml_declares_what_the_code_imports() -> None:
    deps = {e.text for e in ElementTree.parse(ROOT / "package.xml").getroot() if e.tag.endswith("depend")}
    for key in ("rclpy", "rcl_interfaces", "sensor_msgs", "diagnostic_msgs", "geometry_msgs", "ament_index_python", "launch_ros",
                "python3-torch", "python3-rosbags-pip", "python3-onnxruntime-pip", "python3-opencv"):
        assert key in deps, key


def _launch_file() -> ast.Module:
    return ast.parse((ROOT / "launch" / "noise_monitor.launch.py").read_text())


def _calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "id", None) == name]


def test_launch_file_takes_a_camera_namespace_a_params_file_and_remaps_the_relative_inputs() -> None:
    """launch_ros is not installable here: the launch file is checked as source (it compiles, declares its
    arguments and passes them to the node), and generated when launch_ros is importable."""
    tree = _launch_file()
    compile(tree, "noise_monitor.launch.py", "exec")
    inputs = next(n.value for n in ast.walk(tree) if isinstance(n, ast.Assign)
                  and getattr(n.targets[0], "id", None) == "INPUTS")
    assert ast.literal_eval(inputs) == ("image", "metadata", "camera_info", "temperature")
    declared = {c.args[0].value for c in _calls(tree, "DeclareLaunchArgument") if isinstance(c.args[0], ast.Constant)}
    assert {"namespace", "params_file", "log_level"} <= declared  # the inputs' arguments come from INPUTS
    (node,) = _calls(tree, "Node")
    kw = {k.arg: ast.unparse(k.value) for k in node.keywords}
    assert kw["namespace"] == "LaunchConfiguration('namespace')"
    assert kw["parameters"] == "[LaunchConfiguration('params_file')]"
    assert kw["remappings"] == "[(name, LaunchConfiguration(name)) for name in INPUTS]"
    assert kw["executable"] == "'noise_monitor_node'"
    # the relative defaults the remappings act on are the node's parameter defaults
    from noise_monitor.monitor.runtime import parameter_table

    table = parameter_table()
    assert [table[f"{t}_topic"][0] for t in ("image", "metadata", "camera_info", "temperature")] == list(
        ast.literal_eval(inputs))
    if importlib.util.find_spec("launch_ros") is not None:  # with a ROS install: the real description
        spec = importlib.util.spec_from_file_location("nm_launch", ROOT / "launch" / "noise_monitor.launch.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        assert len(module.generate_launch_description().entities) == 8


@pytest.mark.skipif(os.environ.get("NOISE_MONITOR_SKIP_WHEEL") == "1", reason="wheel test disabled")
def test_wheel_installs_into_a_fresh_venv_and_runs(tmp_path: Path) -> None:
    dist = tmp_path / "dist"
    built = _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-w", str(dist), str(ROOT)],
                 cwd=tmp_path)
    assert built.returncode == 0, built.stderr[-2000:]
    (wheel,) = dist.glob("noise_monitor-*.whl")
    env_dir = tmp_path / "venv"
    venv.create(env_dir, with_pip=True)
    py = env_dir / "bin" / "python"
    # the tested pins as constraints (without extras, which pip refuses there): torch 2.13.0 is the local
    # CPU build, not a multi-GB download
    pins = re.sub(r"\[[^]]*\]", "", (ROOT / "requirements.txt").read_text())
    (tmp_path / "constraints.txt").write_text(pins)
    inst = _run([str(py), "-m", "pip", "install", "--quiet", "--disable-pip-version-check", f"{wheel}[ros]",
                 "-c", str(tmp_path / "constraints.txt")], cwd=tmp_path)
    assert inst.returncode == 0, inst.stderr[-3000:]
    cli = env_dir / "bin" / "noise-monitor"
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    for args in (["--help"], ["effects"], ["node", "--help"], ["replay", "--help"]):
        res = _run([str(cli), *args], cwd=tmp_path, env=env)
        assert res.returncode == 0, (args, res.stderr[-2000:])
    # outside the source tree: profiles and parameters come from the installed share folder
    out = tmp_path / "replay"
    res = _run([str(cli), "replay", str(ROOT / "bags" / "icx285_lab.mcap"), "--profile", "icx285", "--out", str(out),
                "--no-plot", "--threads", "1"], cwd=tmp_path, env=env)
    assert res.returncode == 0, res.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["frames_total"] == summary["frames_processed"] + summary["frames_skipped"] > 0


#: colcon from PyPI for the colcon test, pinned: colcon-core 0.21 requires setuptools<80, whose 80 dropped the
#: `setup.py develop --editable` that `colcon build --symlink-install` runs ("option --editable not recognized")
COLCON = ["colcon-common-extensions==0.3.0", "colcon-core==0.21.3", "setuptools<80"]


def _colcon_env(tmp_path: Path) -> dict[str, str]:
    """Environment running ``python -m colcon`` with this interpreter: colcon as a ROS user has it, beside rclpy and
    the package's dependencies, so the installed scripts' shebang is a Python that can run them. Uses an importable
    colcon, else installs colcon into a folder put on PYTHONPATH (the project's venv is left as it is)."""
    env = {**os.environ, "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    if importlib.util.find_spec("colcon_core") is None:
        target = tmp_path / "colcon"
        inst = _run([sys.executable, "-m", "pip", "install", "--quiet", "--disable-pip-version-check", "--target",
                     str(target), *COLCON], cwd=tmp_path)
        assert inst.returncode == 0, inst.stderr[-3000:]
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(target), env.get("PYTHONPATH")) if p)
    return env


def _sourced(ws: Path, *cmd: str) -> list[str]:
    """``cmd`` run in a shell that sourced the workspace's install/setup.bash, as a ROS user's terminal."""
    return ["bash", "-c", 'source install/setup.bash && exec "$@"', "sourced", *cmd]


_LOOKUP = """
import os, sys
from ament_index_python.packages import get_package_prefix, get_package_share_directory
import noise_monitor
from noise_monitor.paths import camera_profile_path, share_dir
prefix = get_package_prefix('noise_monitor')
# what `ros2 run noise_monitor noise_monitor_node` and launch_ros' Node(package=..., executable=...) execute
node = os.path.join(prefix, 'lib', 'noise_monitor', 'noise_monitor_node')
print(node, os.access(node, os.X_OK), get_package_share_directory('noise_monitor'), noise_monitor.__file__,
      share_dir(), camera_profile_path('icx285'), sep='\\n')
"""


@pytest.mark.skipif(os.environ.get("NOISE_MONITOR_SKIP_COLCON") == "1", reason="colcon test disabled")
def test_colcon_build_installs_what_ros2_run_and_ros2_launch_look_up(tmp_path: Path) -> None:
    """`colcon build` (and --symlink-install) of a workspace holding this tree: the ament index entry, the share
    folder (package.xml, launch, config, bags), the package with its estimator weights, and the executables in
    lib/noise_monitor that `ros2 run`/`ros2 launch` start; the node starts from there and stops cleanly on Ctrl-C.
    ros2cli and launch_ros are not installable here: their lookups are made with ament_index_python."""
    env = _colcon_env(tmp_path)
    ignore = shutil.ignore_patterns(".git", ".venv", "build", "install", "log", "out", "__pycache__", "*.egg-info",
                                    ".pytest_cache", ".hypothesis", ".mypy_cache", ".ruff_cache")
    for symlink in (False, True):
        ws = tmp_path / ("ws_symlink" if symlink else "ws")
        shutil.copytree(ROOT, ws / "src" / "noise_monitor", ignore=ignore)
        built = _run([sys.executable, "-m", "colcon", "build", *(["--symlink-install"] if symlink else [])], cwd=ws,
                     env=env)
        assert built.returncode == 0, (symlink, built.stdout[-3000:], built.stderr[-3000:])
        prefix = ws / "install" / "noise_monitor"
        share = prefix / "share" / "noise_monitor"
        assert (prefix / "share" / "ament_index" / "resource_index" / "packages" / "noise_monitor").is_file()
        for rel in ("package.xml", "launch/noise_monitor.launch.py", "config/node.yaml", "config/analyzers.yaml",
                    "config/cameras/icx285.yaml", "config/cameras/ev76c661.yaml", "bags/icx285_lab.mcap"):
            assert (share / rel).is_file(), (symlink, rel)
        for script in ("noise_monitor_node", "noise-monitor"):
            path = prefix / "lib" / "noise_monitor" / script
            assert os.access(path, os.X_OK), (symlink, script)
            assert path.read_text().startswith(f"#!{sys.executable}\n"), path.read_text()[:200]
        run_env = {k: v for k, v in env.items() if k != "PYTHONPATH"}  # a user's shell: colcon's folder is not there
        looked = _run(_sourced(ws, sys.executable, "-c", _LOOKUP), cwd=ws, env=run_env)
        assert looked.returncode == 0, (symlink, looked.stderr[-3000:])
        node, executable, ament_share, module, share_found, profile = looked.stdout.split("\n")[:6]
        assert Path(node) == prefix / "lib" / "noise_monitor" / "noise_monitor_node" and executable == "True"
        assert Path(ament_share) == share
        src = ws / "src" / "noise_monitor"
        if symlink:  # the package and its data are the source tree's (edits take effect without a rebuild)
            assert Path(module).resolve() == src / "noise_monitor" / "__init__.py"
            assert Path(share_found) == src and Path(profile) == src / "config" / "cameras" / "icx285.yaml"
            continue
        site = prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
        assert Path(module) == site / "noise_monitor" / "__init__.py"
        weights = {p.name for p in (site / "noise_monitor" / "estimator" / "weights").iterdir()}
        assert {p.name for p in (ROOT / "noise_monitor" / "estimator" / "weights").iterdir()} <= weights
        assert Path(share_found) == share and Path(profile) == share / "config" / "cameras" / "icx285.yaml"
        cli = _run(_sourced(ws, str(prefix / "lib" / "noise_monitor" / "noise-monitor"), "--help"), cwd=ws, env=run_env)
        assert cli.returncode == 0 and "usage: noise-monitor" in cli.stdout, cli.stderr[-2000:]
        helped = _run(_sourced(ws, node, "--help"), cwd=ws, env=run_env)
        assert helped.returncode == 0 and helped.stdout.startswith("usage: ros2 run noise_monitor"), helped.stderr[-2000:]
        # `ros2 run noise_monitor noise_monitor_node --ros-args --params-file <share>/config/node.yaml`: it runs
        # until Ctrl-C, so: started, its first log line, SIGINT, exit 0
        log = tmp_path / "node.log"
        with log.open("w") as out:
            proc = subprocess.Popen(_sourced(ws, node, "--ros-args", "--params-file", str(share / "config" / "node.yaml")),
                                    cwd=ws, env=run_env, stdout=out, stderr=subprocess.STDOUT)
            try:
                deadline = time.monotonic() + 120
                while "monitoring /image" not in log.read_text() and proc.poll() is None and time.monotonic() < deadline:
                    time.sleep(0.1)
                assert "monitoring /image" in log.read_text(), log.read_text()[-3000:]
                proc.send_signal(signal.SIGINT)
                assert proc.wait(timeout=60) == 0, log.read_text()[-3000:]
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
