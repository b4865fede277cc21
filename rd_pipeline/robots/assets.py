"""Locating robot model files: `RD_ROBOT_ASSETS`, else the `robot_descriptions` unitree_ros clone."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Literal

from rd_pipeline import paths
from rd_pipeline.errors import PipelineError

if TYPE_CHECKING:
    from rd_pipeline.robots.config import RobotConfig


def assets_root() -> Path:
    """A folder laid out like unitree_ros `robots/` (holds `g1_description/`, `h1_description/`, ...)."""
    root = paths.robot_assets_dir()
    if root is not None:
        if not root.is_dir():
            raise PipelineError(f"robot assets {root} (RD_ROBOT_ASSETS or rd-pipeline.toml): not a folder")
        return root
    try:
        from robot_descriptions._cache import clone_to_cache

        return Path(clone_to_cache("unitree_ros")) / "robots"
    except Exception as exc:  # network or git failure: say what to do instead
        raise PipelineError(
            f"robot assets: RD_ROBOT_ASSETS is not set and robot_descriptions could not fetch unitree_ros ({exc})"
        ) from None


def asset_path(relative: str, named_by: str = "") -> Path:
    """A robot model file under the assets folder; `named_by` (the TOML and key that name it)
    goes into the error when it is missing."""
    path = assets_root() / relative
    if not path.is_file():
        by = f", named by {named_by}" if named_by else ""
        raise PipelineError(f"{path}: robot model file not found{by} (check RD_ROBOT_ASSETS)")
    return path


def robot_file(config: RobotConfig, field: Literal["mjcf", "urdf"]) -> Path:
    """The robot's MJCF or URDF, named by `asset.<field>` of its TOML."""
    return asset_path(getattr(config, field), f"asset.{field} of {config.source}")


def model_files(name: str | None) -> dict[str, Path]:
    """The files that define a robot (its config and MJCF), as hashed inputs of the stages that use it."""
    from rd_pipeline.robots.config import load_robot_config

    if name is None:
        raise PipelineError("this stage needs --robot")
    config = load_robot_config(name)
    return {"robot_config": config.source, "mjcf": robot_file(config, "mjcf")}
