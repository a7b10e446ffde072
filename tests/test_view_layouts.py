"""The shipped Foxglove layout and RViz config name only topics (and fields) of the contract.

The topic contract is the README's table; each topic a panel shows must be a row of it, each
plotted field must exist in that topic's message type, the layout's panel tree and its panel
configurations must match, and the views use the markers' frame (``world``).
"""

from __future__ import annotations

import importlib
import json
import re
from pathlib import Path
from typing import Any

import pytest
import yaml
from bfr_model.param_file import config_path
from bfr_ros.markers import WORLD_FRAME

ROOT = Path(__file__).resolve().parents[1]


def contract() -> dict[str, str]:
    """Topic -> type (``pkg/Type``) from the README's "Topic contract" table."""
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Topic contract"):]
    section = section[:section.index("\n## ", 10)]
    rows = re.findall(r"^\| `(/[^`]+)` \| `([\w/]+)` \|", section, flags=re.M)
    assert len(rows) >= 8, rows
    return dict(rows)


def layout_topics(cfg: dict[str, Any]) -> dict[str, set[str]]:
    """Every topic a Foxglove layout's panels name -> the fields it reads ("" for a topic)."""
    out: dict[str, set[str]] = {}

    def add(path: str) -> None:
        topic, _, field = path.partition(".")
        out.setdefault(topic, set()).add(field)

    for panel, c in cfg["configById"].items():
        kind = panel.split("!")[0]
        for topic in c.get("topics", {}):
            add(topic)
        mode = c.get("imageMode", {})
        for key in ("imageTopic", "calibrationTopic"):
            if mode.get(key):
                add(mode[key])
        for topic in mode.get("annotations", {}):
            add(topic)
        if kind in ("Plot", "StateTransitions"):
            assert c["paths"], panel
            for p in c["paths"]:
                add(p["value"])
    return out


def leaves(tree: Any) -> list[str]:
    if isinstance(tree, str):
        return [tree]
    return leaves(tree["first"]) + leaves(tree["second"])


def message_fields(type_name: str) -> dict[str, str]:
    pkg, name = type_name.split("/")
    return importlib.import_module(f"{pkg}.msg").__dict__[name].get_fields_and_field_types()


@pytest.fixture(scope="module")
def layout() -> dict[str, Any]:
    return json.loads(config_path("bfr_tools", "foxglove_layout.json").read_text())


def test_layout_names_only_contract_topics_and_fields(layout: dict[str, Any]) -> None:
    topics = contract()
    named = layout_topics(layout)
    assert set(named) <= set(topics), sorted(set(named) - set(topics))
    for topic, fields in named.items():
        have = message_fields(topics[topic])
        for f in fields - {""}:
            base = re.sub(r"\[\d+\]$", "", f)  # data[0]
            assert base in have, f"{topic}.{f}: not a field of {topics[topic]} ({sorted(have)})"


def test_layout_has_the_views_the_issue_asks_for(layout: dict[str, Any]) -> None:
    cfg = layout["configById"]
    assert sorted(leaves(layout["layout"])) == sorted(cfg)  # every panel placed, none missing
    three_d = [c for k, c in cfg.items() if k.startswith("3D!")]
    assert three_d and three_d[0]["followTf"] == WORLD_FRAME
    assert {"/sim_markers", "/ball_markers"} <= set(three_d[0]["topics"])
    image = next(c["imageMode"] for k, c in cfg.items() if k.startswith("Image!"))
    assert image["imageTopic"] == "/camera/image_raw"
    assert "/camera/detection" in image["annotations"]
    plotted = {p["value"] for k, c in cfg.items() if k.startswith("Plot!") for p in c["paths"]}
    assert {"/controller_state.y", "/controller_state.z", "/controller_state.torque",
            "/controller_state.phi_dot"} <= plotted


def test_rviz_config_uses_world_and_contract_topics() -> None:
    cfg = yaml.safe_load(config_path("bfr_tools", "bfr.rviz").read_text())
    vm = cfg["Visualization Manager"]
    assert vm["Global Options"]["Fixed Frame"] == WORLD_FRAME
    topics = contract()
    named = {d["Topic"]["Value"]: d["Class"] for d in vm["Displays"] if "Topic" in d}
    assert set(named) <= set(topics) and {"/sim_markers", "/ball_markers"} <= set(named)
    for topic, cls in named.items():  # the display matches the topic's type
        kind = topics[topic].split("/")[1]
        assert cls.endswith("/" + kind), (topic, cls, kind)


def test_recorder_records_the_markers_by_default() -> None:
    rec = yaml.safe_load(config_path("bfr_sim", "recorder_node.yaml").read_text())
    topics = rec["/**"]["ros__parameters"]["recorder"]["topics"]
    assert {"sim_markers", "ball_markers", "camera/detection"} <= set(topics)
    c = contract()
    assert all("/" + t in c for t in topics)
