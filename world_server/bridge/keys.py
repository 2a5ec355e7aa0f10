"""The link keys a bridge is given: one per robot it serves, never the robots' run keys.

``swarm run`` hands them over in the environment variable ``BESTOFN_LINK_KEYS``, set for
the bridge only (the bridge takes it out of its environment at once); a bridge started by
hand reads them from a file (``--link-keys``), mode 0600. Either is one JSON object::

    {"v": 1, "run": "<run id>", "links": {"8": "<64 hex digits>", "9": "..."}}

with each key ``bestofn_swarm.link.core.codec.link_key`` of the robot's run key.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from pathlib import Path

from bestofn_swarm.wire import names

LINK_KEYS_ENV = "BESTOFN_LINK_KEYS"
KEY_BYTES = 32


def to_text(run: str, keys: Mapping[int, bytes]) -> str:
    links = {str(robot): key.hex() for robot, key in sorted(keys.items())}
    return json.dumps({"v": 1, "run": run, "links": links}, separators=(",", ":"))


def from_text(text: str, run: str) -> dict[int, bytes]:
    """The link keys in ``text``; ValueError says what is wrong (never echoes a key)."""
    try:
        content = json.loads(text)
    except ValueError:
        raise ValueError("not JSON") from None
    if not isinstance(content, dict) or content.get("v") != 1:
        raise ValueError('not a link key object ({"v": 1, ...})')
    if content.get("run") != run:
        raise ValueError(f"the link keys are for run {content.get('run')!r}, not {run!r}")
    links = content.get("links")
    if not isinstance(links, dict):
        raise ValueError('no "links"')
    keys: dict[int, bytes] = {}
    for name, value in links.items():
        robot = names.robot_of_name(str(name))
        try:
            key = bytes.fromhex(value)
        except (TypeError, ValueError):
            raise ValueError(f"the link key of {name!r} is not hexadecimal") from None
        if robot is None or len(key) != KEY_BYTES:
            raise ValueError(f"{name!r}: a robot id and a {KEY_BYTES}-byte key")
        keys[robot] = key
    return keys


def load(run: str, path: Path | None) -> dict[int, bytes]:
    """The link keys from the launcher's variable (taken out of the environment), else from
    ``path``; ValueError if there are none or they are not right."""
    text = os.environ.pop(LINK_KEYS_ENV, None)
    if text is None and path is not None:
        try:
            text = path.read_text()
        except OSError as error:
            raise ValueError(f"cannot read {path}: {error.strerror}") from None
    if text is None:
        raise ValueError(f"no link keys: ${LINK_KEYS_ENV} or --link-keys FILE")
    return from_text(text, run)
