"""Robots: TOML configs, asset resolution, and validated MuJoCo / Pinocchio models.

The model half (MuJoCo, Pinocchio) loads on first use, so commands that only plan the DAG stay fast.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from rd_pipeline.robots.config import RobotConfig, available_robots, load_robot_config

if TYPE_CHECKING:
    from rd_pipeline.robots.model import Robot, load_pinocchio_model, load_robot

__all__ = ["Robot", "RobotConfig", "available_robots", "load_pinocchio_model", "load_robot", "load_robot_config"]

_MODEL_NAMES = ("Robot", "load_pinocchio_model", "load_robot")


def __getattr__(name: str) -> object:
    if name in _MODEL_NAMES:
        from rd_pipeline.robots import model

        return getattr(model, name)
    raise AttributeError(f"module 'rd_pipeline.robots' has no attribute '{name}'")
