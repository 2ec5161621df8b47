"""Typed config: YAML inheritance, strict keys and types, overrides, save/load, help."""

from __future__ import annotations

import dataclasses
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import pytest
import yaml

from eslam.config import (
    DataConfig,
    ESLAMConfig,
    SceneConfig,
    config_from_dict,
    config_help,
    config_to_dict,
    field_docs,
    load_config,
    save_config,
)
from eslam.errors import ConfigError, ESLAMError

CONFIGS = Path(__file__).resolve().parents[1] / "configs"
BOUND = [[-1.0, 1.0], [-2.0, 2.0], [0.0, 3.0]]


@dataclass
class Inner:
    """A test-only section."""

    mode: Literal["fast", "exact"] = "fast"
    """How to do it."""
    size: tuple[int, int] = (4, 3)
    """Width and height."""
    weights: tuple[float, ...] = (1.0,)
    """Any number of weights."""


@dataclass
class Toy:
    """A test-only schema covering the types the real one does not use yet."""

    name: str = "toy"
    """A name."""
    flag: bool = False
    """A switch."""
    rate: float = 0.5
    """A rate."""
    steps: int = 10
    """A count."""
    inner: Inner = field(default_factory=Inner)
    """A section."""
    extra: Inner | None = None
    """An optional section."""


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def error_of(path: Path | str | None, overrides: tuple[str, ...] = (), schema=ESLAMConfig) -> str:
    with pytest.raises(ConfigError) as caught:
        load_config(path, overrides, schema=schema)
    message = str(caught.value)
    assert "\n" not in message
    return message


def test_base_yaml_holds_every_default() -> None:
    assert load_config(CONFIGS / "base.yaml") == ESLAMConfig()
    listed = yaml.safe_load((CONFIGS / "base.yaml").read_text())
    for row in config_help(ESLAMConfig):
        node = listed
        for part in row.key.split("."):
            assert part in node, f"configs/base.yaml lacks '{row.key}'"
            node = node[part]


def test_synthetic_yaml_reads_the_replica_layout() -> None:
    config = load_config(CONFIGS / "synthetic.yaml")
    assert config.data.format == "replica"
    assert config.seed == ESLAMConfig().seed


def test_defaults_without_a_file() -> None:
    assert load_config(None) == ESLAMConfig()
    assert load_config(None, ["seed=3"]).seed == 3


def test_inherit_chain_of_three_files_deep_merges(tmp_path: Path) -> None:
    write(tmp_path / "a.yaml", "seed: 1\nthreads: 4\ndata: {format: tum, path: /a}\n")
    write(tmp_path / "sub/b.yaml", "inherit_from: ../a.yaml\nthreads: 3\ndata: {path: /b}\n")
    child = write(tmp_path / "sub/c.yaml", f"inherit_from: b.yaml\nscene: {{bound: {BOUND}}}\n")
    config = load_config(child)
    assert (config.seed, config.threads) == (1, 3)
    assert config.data == DataConfig(format="tum", path="/b")
    assert config.scene.bound == BOUND


def test_inherit_from_a_list_applies_in_order(tmp_path: Path) -> None:
    write(tmp_path / "one.yaml", "seed: 1\nthreads: 1\n")
    write(tmp_path / "two.yaml", "seed: 2\n")
    child = write(tmp_path / "c.yaml", "inherit_from: [one.yaml, two.yaml]\n")
    assert (load_config(child).seed, load_config(child).threads) == (2, 1)


def test_inheritance_cycle_is_an_error(tmp_path: Path) -> None:
    write(tmp_path / "a.yaml", "inherit_from: b.yaml\n")
    write(tmp_path / "b.yaml", "inherit_from: a.yaml\n")
    message = error_of(tmp_path / "a.yaml")
    assert "cycle" in message
    assert "a.yaml -> b.yaml -> a.yaml" in message


def test_missing_inherit_target_names_the_file(tmp_path: Path) -> None:
    child = write(tmp_path / "child.yaml", "inherit_from: nowhere.yaml\n")
    message = error_of(child)
    assert message.startswith(f"{child}:")
    assert "nowhere.yaml" in message


def test_missing_file_and_bad_yaml(tmp_path: Path) -> None:
    assert "not found" in error_of(tmp_path / "absent.yaml")
    broken = write(tmp_path / "broken.yaml", "seed: [1,\n")
    assert error_of(broken).startswith(f"{broken}: invalid YAML")
    assert "mapping" in error_of(write(tmp_path / "list.yaml", "- 1\n"))


def test_unknown_key_in_child_names_that_file(tmp_path: Path) -> None:
    write(tmp_path / "parent.yaml", "seed: 1\n")
    child = write(tmp_path / "child.yaml", "inherit_from: parent.yaml\ndata: {pth: /x}\n")
    message = error_of(child)
    assert message.startswith(f"{child}:")
    assert "'data.pth'" in message
    assert "did you mean 'data.path'?" in message


def test_unknown_key_in_parent_names_the_parent(tmp_path: Path) -> None:
    write(tmp_path / "parent.yaml", "treads: 1\n")
    child = write(tmp_path / "child.yaml", "inherit_from: parent.yaml\nseed: 2\n")
    message = error_of(child)
    assert message.startswith(f"{tmp_path / 'parent.yaml'}:")
    assert "'treads'" in message and "did you mean 'threads'?" in message


def test_unknown_key_with_nothing_close_lists_the_valid_keys(tmp_path: Path) -> None:
    message = error_of(write(tmp_path / "c.yaml", "scene: {zzzz: 1}\n"))
    assert "'scene.zzzz'" in message and "bound" in message


def test_unknown_override_names_the_command_line() -> None:
    message = error_of(CONFIGS / "base.yaml", ("scene.bund=null",))
    assert message.startswith("command line:")
    assert "'scene.bund'" in message and "did you mean 'scene.bound'?" in message
    assert error_of(None, ("seed",)).startswith("command line:")
    assert "section" in error_of(None, ("data={path: /x}",))
    assert "not a section" in error_of(None, ("seed.x=1",))


def test_typed_overrides() -> None:
    config = load_config(
        None,
        ["threads=0", "scene.bound=[[-1, 1], [-2, 2], [0, 3]]", "data.path=/x/y", "seed=7"],
    )
    assert (config.threads, config.seed, config.data.path) == (0, 7, "/x/y")
    assert config.scene.bound == BOUND
    assert all(isinstance(v, float) for pair in config.scene.bound for v in pair)
    assert load_config(None, ["data.path=null"]).data.path is None
    assert load_config(None, ["data.path=2024"]).data.path == "2024"  # text stays text
    toy = load_config(None, ["rate=1e-3", "flag=true", "steps=2.0", "inner.size=[8, 6]"], Toy)
    assert toy.rate == pytest.approx(1e-3) and isinstance(toy.rate, float)
    assert toy.flag is True
    assert toy.steps == 2 and isinstance(toy.steps, int)
    assert toy.inner.size == (8, 6)


def test_float_written_without_a_dot_is_parsed(tmp_path: Path) -> None:
    toy = load_config(write(tmp_path / "t.yaml", "rate: 1e-3\n"), schema=Toy)
    assert toy.rate == pytest.approx(1e-3)


def test_int_field_rejects_fractions_text_and_bools(tmp_path: Path) -> None:
    message = error_of(write(tmp_path / "f.yaml", "seed: 1.5\n"))
    assert message.startswith(f"{tmp_path / 'f.yaml'}:")
    assert "'seed'" in message and "int" in message and "1.5" in message
    message = error_of(None, ("threads=abc",))
    assert "'threads' expects int" in message and "'abc'" in message
    assert "True" in error_of(None, ("seed=true",))


def test_float_and_bool_fields_reject_the_wrong_kinds() -> None:
    assert "expects float" in error_of(None, ("rate=yes",), Toy)
    assert "expects bool" in error_of(None, ("flag=1",), Toy)
    assert "expects str" in error_of(None, ("name=null",), Toy)


def test_literal_choices_are_checked() -> None:
    assert load_config(None, ["inner.mode=exact"], Toy).inner.mode == "exact"
    message = error_of(None, ("inner.mode=fsat",), Toy)
    assert "'inner.mode'" in message and "'fast', 'exact'" in message
    assert "did you mean 'fast'?" in message


def test_tuples_and_optional_sections() -> None:
    toy = config_from_dict({"inner": {"weights": [1, 2, 3]}, "extra": {"mode": "exact"}}, Toy)
    assert toy.inner.weights == (1.0, 2.0, 3.0)
    assert toy.extra == Inner(mode="exact")
    assert config_from_dict({"extra": None}, Toy).extra is None
    with pytest.raises(ConfigError, match=r"'inner\.size' expects tuple\[int, int\].*2 items"):
        config_from_dict({"inner": {"size": [1, 2, 3]}}, Toy, source="test.yaml")
    with pytest.raises(ConfigError, match=r"^test\.yaml: 'inner' is a section"):
        config_from_dict({"inner": 3}, Toy, source="test.yaml")


def test_post_init_checks_name_the_file_and_key(tmp_path: Path) -> None:
    bad = write(tmp_path / "bad.yaml", "scene: {bound: [[0, 1], [1, 0], [0, 1]]}\n")
    message = error_of(bad)
    assert message.startswith(f"{bad}: scene.bound must be 3 pairs")
    message = error_of(CONFIGS / "base.yaml", ("threads=-1",))
    assert message.startswith("command line: threads must be >= 0")
    assert "'gpu'" in error_of(None, ("device=gpu",))
    with pytest.raises(ValueError, match="bound"):
        SceneConfig(bound=[[0.0, 1.0]])


@pytest.mark.parametrize(
    ("override", "least"),
    [
        ("tracking.render.iterations=-1", 1),
        ("tracking.render.iterations=0", 1),
        ("tracking.render.rays=0", 1),
        ("tracking.sdf.iterations=0", 1),
        ("tracking.hybrid.render_iterations=0", 1),
        ("mapping.rays=0", 1),
        ("mapping.iterations=-1", 0),
        ("mapping.first_iterations=-1", 0),
        ("mapping.first_rays=0", 1),
        ("render.samples_stratified=0", 1),
        ("render.samples_surface=-1", 0),
    ],
)
def test_counts_are_checked_at_load_naming_the_key(override: str, least: int) -> None:
    """Issue 15: tracking.iterations=-1 and tracking.rays=0 were accepted; a combined check
    ("iterations and rays must be >= 1") blamed the file that set the other key."""
    key = override.split("=")[0]
    message = error_of(CONFIGS / "base.yaml", (override,))
    assert message.startswith(f"command line: {key} must be >= {least}"), message


@pytest.mark.parametrize(
    ("override", "got"),
    [
        ("tracking.sdf.colour_weight=-0.1", "-0.1"),
        ("tracking.sdf.colour_robust_scale=0", "0.0"),
        ("tracking.sdf.robust_scale=0", "0.0"),
        ("tracking.sdf.max_sdf=1.5", "1.5"),
        ("tracking.sdf.min_inlier_fraction=1.0", "1.0"),
        ("tracking.sdf.max_residual=-0.01", "-0.01"),
        ("scene.grow_margin=-0.1", "-0.1"),
        ("field.decoder_layers=0", "0"),
        ("field.beta_init=0", "0.0"),
        ("field.bound_multiple=-1", "-1.0"),
        ("render.far_factor=1.0", "1.0"),
        ("output.checkpoint_every=0", "0"),
        ("output.mesh_resolution=0", "0.0"),
        ("scene.max_extent=.nan", "nan"),
        ("render.surface_band=.nan", "nan"),
        ("tracking.sdf.degeneracy=.nan", "nan"),
        ("mapping.loops.anchor_sigma=[0.01,-1]", "[0.01, -1.0]"),
    ],
)
def test_checks_name_one_key_and_its_value(override: str, got: str) -> None:
    """Each setting is checked on its own: a combined check ("robust_scale must be > 0
    and max_sdf in (0, 1]") named neither the bad key nor its value. NaN fails the
    checks too ("x <= 0" let it through)."""
    key = override.split("=")[0]
    message = error_of(CONFIGS / "base.yaml", (override,))
    assert message.startswith(f"command line: {key} must be"), message
    assert message.endswith(f"got {got}"), message


@pytest.mark.parametrize("override", ["mapping.window=2", "field.truncation=0"])
def test_a_bad_value_from_the_command_line_blames_the_command_line(
    tmp_path: Path, override: str
) -> None:
    """A check naming several keys ("every must be >= 1, window >= 3") blamed the file
    that set the first of them (configs/base.yaml), not the command line that set the
    bad one."""
    child = write(tmp_path / "child.yaml", f"inherit_from: {CONFIGS / 'base.yaml'}\n")
    message = error_of(child, (override,))
    assert message.startswith("command line: ") and "base.yaml" not in message
    assert override.split(".")[1].split("=")[0] in message


def test_a_bad_value_in_a_file_still_blames_that_file(tmp_path: Path) -> None:
    child = write(
        tmp_path / "child.yaml",
        f"inherit_from: {CONFIGS / 'base.yaml'}\nmapping: {{window: 2}}\n",
    )
    message = error_of(child, ("mapping.every=2",))
    assert message.startswith(f"{child}: ") and "mapping.window must be >= 3" in message


def test_config_error_is_a_user_error() -> None:
    assert issubclass(ConfigError, ESLAMError)


def test_save_then_load_round_trips(tmp_path: Path) -> None:
    config = load_config(CONFIGS / "synthetic.yaml", ["seed=5", f"scene.bound={BOUND}"])
    save_config(config, tmp_path / "run" / "config.yaml")
    text = (tmp_path / "run" / "config.yaml").read_text()
    assert "!!" not in text  # no python tags
    plain = yaml.safe_load(text)
    assert plain == config_to_dict(config)
    assert list(plain) == [f.name for f in dataclasses.fields(ESLAMConfig)]
    assert load_config(tmp_path / "run" / "config.yaml") == config


def test_save_round_trips_tuples_and_text_that_looks_like_numbers(tmp_path: Path) -> None:
    toy = load_config(None, ["name=2024", "inner.size=[2, 2]"], Toy)
    assert config_to_dict(toy)["inner"]["size"] == [2, 2]
    save_config(toy, tmp_path / "toy.yaml")
    assert load_config(tmp_path / "toy.yaml", schema=Toy) == toy


def leaf_and_section_fields(schema: type, prefix: str = "") -> list[tuple[str, type, str]]:
    found = []
    hints = typing.get_type_hints(schema)
    for f in dataclasses.fields(schema):
        found.append((prefix + f.name, schema, f.name))
        if dataclasses.is_dataclass(hints[f.name]):
            found += leaf_and_section_fields(hints[f.name], prefix + f.name + ".")
    return found


def test_every_field_of_the_config_has_a_docstring() -> None:
    for key, owner, name in leaf_and_section_fields(ESLAMConfig):
        assert field_docs(owner).get(name, "").strip(), f"'{key}' has no docstring under it"
    assert all(row.doc for row in config_help(ESLAMConfig))


def test_config_help_lists_leaves_with_type_default_and_doc() -> None:
    rows = {row.key: row for row in config_help(ESLAMConfig)}
    assert "data" not in rows and "data.path" in rows
    bound = rows["scene.bound"]
    assert bound.type == "list[list[float]] | null"
    assert bound.default == "null"
    assert "metres" in bound.doc
    assert rows["device"].default == '"cpu"'
    assert config_help(Toy)[-1].key.startswith("extra.")


@pytest.mark.parametrize(
    "name", ["replica/room0", "replica/room0.yaml", "configs/replica/room0.yaml", "demo", "cpu"]
)
def test_a_packaged_config_is_found_by_name_from_any_directory(
    name: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """`eslam run demo.yaml` outside the repository said "config file not found"."""
    monkeypatch.chdir(tmp_path)
    expected = load_config(CONFIGS / f"{name.removeprefix('configs/').removesuffix('.yaml')}.yaml")
    assert load_config(name) == expected


def test_a_path_that_exists_wins_over_a_packaged_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.chdir(tmp_path)
    write(tmp_path / "demo.yaml", "seed: 7\n")
    assert load_config("demo.yaml").seed == 7
    assert load_config("demo").seed == load_config(CONFIGS / "demo.yaml").seed


def test_an_unknown_config_name_suggests_the_closest_and_eslam_configs(tmp_path: Path) -> None:
    message = error_of("replica/room9")
    assert "did you mean 'replica/room" in message and "eslam configs" in message
