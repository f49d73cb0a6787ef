"""The shipped plotting layouts (layouts/, written by scripts/make_layouts.py): each references
only topics and array elements the node publishes for its configuration's models, names every
parameter with its estimate and corrected +-2 sigma curves, pairs estimate and standard error by
the sample stamp where the tool can (Foxglove), equals the generator's output, follows a
namespace when generated for one, and is installed by setup.py. No GUI: what the tools do with
the files is not exercised here."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from rls_uncertainty.datapath.outputs import NODE_NAME, output_topics
from rls_uncertainty.settings import load_parameters_file, pipeline_config

ROOT = Path(__file__).resolve().parents[1]
LAYOUTS = ROOT / "layouts"
CONFIGS = sorted(p.stem for p in (ROOT / "config").glob("*.yaml"))


def _generator():
    spec = importlib.util.spec_from_file_location("make_layouts", ROOT / "scripts" / "make_layouts.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _models(config: str) -> dict[str, list[str]]:
    cfg = pipeline_config(load_parameters_file(str(ROOT / "config" / f"{config}.yaml")))
    return {m.output: list(m.parameter_names) for m in cfg.models}


NS = ""  # the namespace the layouts under test were generated for


def _node_topics(models) -> set[str]:
    return {f"{NS}/{NODE_NAME}/{t}" for t, _ in output_topics(models)}


def _element(ref: str, models: dict, pattern: str) -> tuple[str, str, int]:
    """``(model, array, index)`` of a reference to an element of a node's array topic; fails
    unless the topic is one the node publishes and the index is within the model's size."""
    m = re.fullmatch(pattern, ref)
    assert m, f"{ref!r} is not an element of a node output array"
    model, array, index = m.group(1), m.group(2), int(m.group(3))
    assert f"{NS}/{NODE_NAME}/{model}/{array}" in _node_topics(models), ref
    assert 0 <= index < len(models[model]), f"{ref}: index beyond {model}'s {len(models[model])} parameters"
    return model, array, index


def test_every_shipped_configuration_has_both_layouts_and_nothing_else_is_there():
    assert CONFIGS == ["t2", "t2_turbulence", "twin_otter_lateral", "twin_otter_longitudinal"]
    assert sorted(p.name for p in LAYOUTS.iterdir()) == sorted(
        f"{c}.{kind}" for c in CONFIGS for kind in ("foxglove.json", "plotjuggler.xml"))


def test_the_layouts_are_the_generators_output():
    files = _generator().generate()
    assert set(files) == set(LAYOUTS.iterdir())
    for path, text in files.items():
        assert path.read_text() == text, f"{path.name} is stale: run scripts/make_layouts.py"
    assert _generator().generate() == files  # deterministic


@pytest.fixture(params=["", "/fleet/a1"], ids=["shipped", "namespace"])
def layouts(request, tmp_path, monkeypatch):
    """The shipped layouts/, and the generator's layouts for a node under a namespace."""
    monkeypatch.setattr(sys.modules[__name__], "NS", request.param)
    if not request.param:
        return LAYOUTS
    for path, text in _generator().generate(request.param, tmp_path).items():
        path.write_text(text)
    return tmp_path


@pytest.mark.parametrize("config", CONFIGS)
def test_the_plotjuggler_layout_plots_every_parameter_from_published_topics(config, layouts):
    models = _models(config)
    root = ET.parse(layouts / f"{config}.plotjuggler.xml").getroot()
    pattern = rf"{NS}/{NODE_NAME}/(\w+)/(estimates|standard_errors)/data\[(\d+)\]"
    snippets = {s.get("name"): s for s in root.iter("snippet")}
    for name, s in snippets.items():
        assert s.get("language") == "LUA"
        model, array, i = _element(s.findtext("linked_source"), models, pattern)
        assert array == "estimates"
        parameter = models[model][i]
        extra = [v.text for v in s.find("additional_sources") or []]
        function = s.findtext("function")
        if name == f"{parameter} estimate":
            assert (function, extra) == ("return value", [])
        else:  # the bounds: estimate +- 2 x the corrected standard error of the same parameter
            sign = {f"{parameter} +2sigma": "+", f"{parameter} -2sigma": "-"}[name]
            assert function == f"return value {sign} 2 * v1"
            assert [_element(e, models, pattern) for e in extra] == [(model, "standard_errors", i)]
    curves = [c.get("name") for c in root.iter("curve")]
    assert sorted(curves) == sorted(snippets)  # every curve is computed, every computation plotted
    wanted = {f"{p}{q}" for names in models.values() for p in names for q in (" estimate", " +2sigma", " -2sigma")}
    assert set(curves) == wanted
    tabs = [t.get("tab_name") for t in root.iter("Tab")]
    assert tabs == list(models)
    (selected,) = [e.get("value") for e in root.iter("selected_topics")]
    assert set(selected.split(";")) <= _node_topics(models)


@pytest.mark.parametrize("config", CONFIGS)
def test_the_foxglove_layout_plots_every_parameter_paired_by_stamp_from_published_topics(config, layouts):
    models = _models(config)
    layout = json.loads((layouts / f"{config}.foxglove.json").read_text())
    assert set(layout) == {"configById", "globalVariables", "userNodes", "playbackConfig", "layout"}
    scripts = {}
    for script in layout["userNodes"].values():
        code = script["sourceCode"]
        inputs = json.loads(re.search(r"^export const inputs = (\[.*\]);$", code, re.M).group(1))
        output = re.search(r'^export const output = "(.*)";$', code, re.M).group(1)
        assert set(inputs) <= _node_topics(models), inputs
        assert output.startswith(f"/foxglove_script{NS}/")
        model = re.fullmatch(rf"{NS}/{NODE_NAME}/(\w+)/estimates", inputs[0]).group(1)
        assert inputs == [f"{NS}/{NODE_NAME}/{model}/estimates", f"{NS}/{NODE_NAME}/{model}/standard_errors"]
        # One field per parameter from the same index of both arrays.
        fields = re.findall(r"^    (\w+): bounds\(e\[(\d+)\], s\[(\d+)\]\),$", code, re.M)
        assert [(f, int(i)) for f, i, j in fields if i == j] == [(p, k) for k, p in enumerate(models[model])]
        assert "lower: estimate - 2 * se, upper: estimate + 2 * se" in code
        assert "estimates.stamp !== errors.stamp" in code  # paired by the sample stamp
        assert "header: { stamp: time(estimates.stamp)" in code  # plotted at the sample's time
        assert "dim[dim.length - 1]?.label" in code  # the stamp is in the last dim
        scripts[output] = model
    assert sorted(scripts.values()) == sorted(models)
    labels = []
    for panel_id, panel in layout["configById"].items():
        if not panel_id.startswith("Plot!"):
            continue
        for series in panel["paths"]:
            labels.append(series["label"])
            assert series["timestampMethod"] == "headerStamp"
            m = re.fullmatch(r"(/foxglove_script[\w/]*)\.(\w+)\.(estimate|upper|lower)", series["value"])
            assert m, series["value"]  # every curve from a user script of this layout
            model = scripts[m.group(1)]
            assert m.group(2) in models[model]
            suffix = {"estimate": "", "upper": " +2sigma", "lower": " -2sigma"}[m.group(3)]
            assert series["label"] == f"{m.group(2)}{suffix}"
    wanted = [f"{p}{q}" for names in models.values() for p in names for q in ("", " +2sigma", " -2sigma")]
    assert sorted(labels) == sorted(wanted)
    tabs = layout["configById"][layout["layout"]]["tabs"]
    assert [t["title"] for t in tabs] == list(models)


def test_the_stamp_label_parser_of_the_foxglove_script_reads_what_the_node_writes():
    """The script's time() takes "stamp:SEC.NANOSEC" apart as messages.parse_stamp_label does."""
    from rls_uncertainty.datapath.outputs import parse_stamp_label, stamp_label

    code = json.loads((LAYOUTS / "t2.foxglove.json").read_text())["userNodes"]["rls_CZ_bounds"]["sourceCode"]
    assert 'const [sec, nsec] = label.slice(6).split(".");' in code
    for stamp in (0, 1_767_225_600_140_000_000, 5_000_000_001):
        label = stamp_label(stamp)
        sec, nsec = label[6:].split(".")  # what the script does
        assert int(sec) * 1_000_000_000 + int(nsec) == parse_stamp_label(label) == stamp


def test_setup_installs_the_layouts():
    text = (ROOT / "setup.py").read_text()
    assert '(f"share/{PACKAGE}/layouts", glob("layouts/*"))' in text
