"""The bag-input command-line options of `replay` and `analyze`: which topics to read, the pixels' bit depth."""
from __future__ import annotations

import argparse
from typing import Any

#: the topic roles a bag reader detects and the options that override them
TOPIC_ROLES = ("image", "metadata", "camera_info", "temperature")


def add_input_arguments(parser: argparse.ArgumentParser) -> None:
    """--image-topic, --metadata-topic, --camera-info-topic, --temperature-topic and --bit-depth."""
    names = {"image": "image", "metadata": "metadata", "camera_info": "CameraInfo", "temperature": "Temperature"}
    for role in TOPIC_ROLES:
        parser.add_argument(f"--{role.replace('_', '-')}-topic",
                            help=f"override the auto-detected {names[role]} topic")
    parser.add_argument("--bit-depth", type=int, help="bits per pixel of 16-bit images (default: profile)")


def topic_overrides(args: argparse.Namespace) -> dict[str, Any]:
    """The topic options given, as keyword arguments of :func:`noise_monitor.bag.reader.open_bag`."""
    return {f"{role}_topic": getattr(args, f"{role}_topic") for role in TOPIC_ROLES}
