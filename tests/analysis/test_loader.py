"""The one parser of scene files (analysis.loader.parse_scene_data): limits on size, nesting
depth and YAML aliases, JSON-only values, one-line errors; the public names still work."""

from __future__ import annotations

import json
import time
import tracemalloc
from pathlib import Path

import pytest
import yaml

from analysis.exceptions import SceneError
from analysis.loader import (
    MAX_SCENE_DEPTH,
    MAX_YAML_ALIASES,
    YAML_LOADERS,
    load_scene,
    parse_scene_data,
    parse_scene_text,
    read_scene_data,
)

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"
PLANAR = EXAMPLES / "planar_disk_envelope.json"


def alias_bomb(levels: int = 9, width: int = 6) -> str:
    """The 'billion laughs' of YAML: each level a list of ``width`` aliases of the level before
    (9 x 6: a few hundred bytes that would build 6**9 = 10 million values)."""
    names = [f"l{i}" for i in range(levels)]
    lines = [f"{names[0]}: &{names[0]} [" + ", ".join(["x"] * width) + "]"]
    for i in range(1, levels):
        lines.append(f"{names[i]}: &{names[i]} [" + ", ".join([f"*{names[i - 1]}"] * width) + "]")
    return "\n".join(lines) + "\n"


@pytest.fixture(params=YAML_LOADERS, ids=lambda c: c.__name__)
def loader(request: pytest.FixtureRequest) -> type:
    """Each YAML reader: libyaml's (C, the default where PyYAML has it) and PyYAML's own."""
    return request.param  # type: ignore[no-any-return]


def _error(source: str | bytes, suffix: str, loader: type | None = None, **kw: int) -> SceneError:
    with pytest.raises(SceneError) as info:
        parse_scene_data(source, suffix, yaml_loader=loader, **kw)
    message = str(info.value)
    assert "\n" not in message and "Traceback" not in message, message
    return info.value


def test_alias_bomb_is_refused_fast_and_small(loader: type) -> None:
    bomb = alias_bomb()
    assert len(bomb.encode()) < 400
    tracemalloc.start()
    t0 = time.perf_counter()
    try:
        e = _error(bomb, ".yaml", loader)
        elapsed = time.perf_counter() - t0
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert "aliases" in str(e) and str(MAX_YAML_ALIASES) in str(e)
    assert elapsed < 0.5 and peak < 20_000_000, (elapsed, peak)


def test_wide_alias_expansion_under_the_alias_count_is_refused(loader: type) -> None:
    """Few aliases, but each of a large list: refused by the expanded size, not built."""
    big = "[" + ", ".join(["1"] * 20_000) + "]"
    text = f"a: &a {big}\n" + "".join(f"b{i}: *a\n" for i in range(20))
    assert "expand to more than" in str(_error(text, ".yaml", loader))


def test_recursive_alias_is_refused(loader: type) -> None:
    assert "recursive" in str(_error("a: &a [1, *a]\n", ".yaml", loader))


def test_a_few_aliases_still_work(loader: type) -> None:
    text = "r: &r 0.5\nlinks: [{length: 1, radius: *r}, {length: 2, radius: *r}]\n"
    assert parse_scene_data(text, ".yaml", yaml_loader=loader) == {
        "r": 0.5, "links": [{"length": 1, "radius": 0.5}, {"length": 2, "radius": 0.5}]}


@pytest.mark.parametrize(("text", "suffix"), [
    ("[" * 100_000 + "]" * 100_000, ".json"),
    ('{"a": ' * 100_000 + "1" + "}" * 100_000, ".json"),
    ("[" * 5_000 + "]" * 5_000, ".yaml"),
    ("{a: " * 5_000 + "1" + "}" * 5_000, ".yaml"),
    ("".join("  " * i + "-\n" for i in range(MAX_SCENE_DEPTH + 5)), ".yaml"),
    ("[" * 1_000_000, ".yaml"),
])
def test_deep_nesting_is_refused_naming_the_reason(text: str, suffix: str, loader: type) -> None:
    t0 = time.perf_counter()
    e = _error(text, suffix, loader, max_bytes=5_000_000)
    assert f"nested more than {MAX_SCENE_DEPTH} levels deep" in str(e)
    assert time.perf_counter() - t0 < 1.0


def test_nesting_at_the_limit_is_accepted() -> None:
    depth = MAX_SCENE_DEPTH - 1
    assert parse_scene_data("[" * depth + "]" * depth, ".json") is not None


@pytest.mark.parametrize(("text", "loc", "what"), [
    ("name: 2020-01-01\n", ("name",), "a YAML date"),
    ("name: 2020-01-01T10:00:00\n", ("name",), "a YAML timestamp"),
    ("name: !!binary aGVsbG8=\n", ("name",), "!!binary"),
    ("fingers: [{name: a, q: !!set {1, 2}}]\n", ("fingers", 0, "q"), "!!set"),
    ("contacts: !!omap [{a: 1}]\n", ("contacts", 0), "pair"),
    ("1: one\n", (), "mapping key 1 is not a string"),
])
def test_yaml_values_that_are_not_json_name_the_field(text: str, loc: tuple[object, ...], what: str,
                                                      loader: type) -> None:
    e = _error(text, ".yaml", loader)
    assert e.loc == loc and what in str(e), str(e)


def test_yaml_python_tags_are_refused(loader: type) -> None:
    text = "!!python/object/apply:os.system [ls]\n"
    assert "could not determine a constructor" in str(_error(text, ".yaml", loader))


def test_yaml_tab_error_is_one_line_with_its_place(loader: type) -> None:
    e = _error("dim: 2\n\tname: x\n", ".yaml", loader)
    assert str(e).startswith("scene: cannot parse YAML: line 2, column 1:") and ("'\\t'" in str(e) or "tab" in str(e))


@pytest.mark.parametrize("path", sorted(EXAMPLES.glob("*.json")), ids=lambda p: p.stem)
def test_yaml_loaders_read_every_example_as_its_json(path: Path, loader: type) -> None:
    """Both YAML readers give the JSON's own values for every example written out as YAML (the
    block style, and the flow style that nests brackets like JSON)."""
    data = json.loads(path.read_text())
    for flow in (False, True):
        assert parse_scene_data(yaml.safe_dump(data, default_flow_style=flow), ".yaml", yaml_loader=loader) == data


@pytest.mark.parametrize(("text", "where"), [
    ("dim: 2\ncontacts: []\nname: a\ncontacts: [1]\n",
     "line 4, column 1: duplicate key 'contacts' (first written at line 2)"),
    ("object: {radius: 1, radius: 2}\n", "line 1, column 21: duplicate key 'radius' (first written at line 1)"),
    ("fingers:\n  - name: f\n    links: []\n    name: g\n",
     "line 4, column 5: duplicate key 'name' (first written at line 2)"),
])
def test_yaml_duplicate_keys_are_refused_with_their_lines(text: str, where: str, loader: type) -> None:
    """A key written twice in one mapping is refused (PyYAML would keep the last silently)."""
    assert str(_error(text, ".yaml", loader)) == f"scene: cannot parse YAML: {where}; write each key once"


def test_yaml_equal_keys_in_different_mappings_merges_and_aliases_are_kept(loader: type) -> None:
    text = "a: &m {k: 1}\nb: *m\nc: {k: 2, <<: *m}\nd: [{k: 3}, {k: 4}]\n"
    assert parse_scene_data(text, ".yaml", yaml_loader=loader) == {
        "a": {"k": 1}, "b": {"k": 1}, "c": {"k": 2}, "d": [{"k": 3}, {"k": 4}]}


def test_json_duplicate_keys_are_refused() -> None:
    e = _error('{"dim": 2, "contacts": [], "contacts": [1]}', ".json")
    assert str(e) == "scene: cannot parse JSON: duplicate key 'contacts' in one object; write each key once"
    assert e.errors[0]["type"] == "scene_file"
    assert parse_scene_data('{"a": {"k": 1}, "b": {"k": 2}}') == {"a": {"k": 1}, "b": {"k": 2}}


def test_json_syntax_error_names_line_and_column() -> None:
    assert "line 2, column 1" in str(_error('{"a": 1,\n}', ".json"))


@pytest.mark.parametrize("raw", [b"\xff\xfe\x00\x01binary", b"\x89PNG\r\n\x1a\n\x00\x00", "caf\xe9".encode("latin-1")])
def test_binary_and_non_utf8_bytes_are_refused(raw: bytes) -> None:
    e = _error(raw, ".json")
    assert "not UTF-8 text" in str(e) or "binary data" in str(e), str(e)


def test_size_limit() -> None:
    assert "file too large" in str(_error("[" + "1," * 600 + "1]", ".json", max_bytes=1000))


def test_huge_integer_is_a_clean_error() -> None:
    assert "4300 digits" in str(_error("1" * 5000, ".json"))


def test_public_names_still_work(tmp_path: Path) -> None:
    scene = load_scene(PLANAR)
    text = PLANAR.read_text()
    assert parse_scene_text(text, ".json") == scene  # the old signature
    assert parse_scene_text(text.encode(), ".json") == scene  # bytes too
    y = tmp_path / "planar.yaml"
    y.write_text(yaml.safe_dump(json.loads(text)))
    assert load_scene(y) == scene
    assert read_scene_data(y) == json.loads(text)


def test_load_scene_errors_are_scene_errors(tmp_path: Path) -> None:
    binary = tmp_path / "scene.json"
    binary.write_bytes(bytes(range(256)))
    with pytest.raises(SceneError, match=r"not UTF-8 text|binary data"):
        load_scene(binary)
    with pytest.raises(SceneError, match="cannot read"):
        load_scene(tmp_path / "missing.json")
    with pytest.raises(SceneError, match="cannot read"):
        load_scene(tmp_path)  # a folder
