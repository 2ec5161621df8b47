"""Typed configuration: the dataclass tree (schema.py) and its strict YAML loader (loader.py)."""

from eslam.config.loader import (
    COMMAND_LINE,
    FieldHelp,
    config_from_dict,
    config_help,
    config_to_dict,
    field_docs,
    load_config,
    save_config,
)
from eslam.config.schema import (
    MOVED_KEYS,
    DataConfig,
    ESLAMConfig,
    FieldConfig,
    LossConfig,
    LossWeights,
    MappingConfig,
    OutputConfig,
    RenderConfig,
    RenderTrackerConfig,
    SceneConfig,
    TrackingConfig,
)

__all__ = [
    "COMMAND_LINE",
    "MOVED_KEYS",
    "DataConfig",
    "ESLAMConfig",
    "FieldConfig",
    "FieldHelp",
    "LossConfig",
    "LossWeights",
    "MappingConfig",
    "OutputConfig",
    "RenderConfig",
    "RenderTrackerConfig",
    "SceneConfig",
    "TrackingConfig",
    "config_from_dict",
    "config_help",
    "config_to_dict",
    "field_docs",
    "load_config",
    "save_config",
]
