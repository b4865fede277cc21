"""Robots: TOML configs, asset resolution, and validated MuJoCo / Pinocchio models."""

from rd_pipeline.robots.config import RobotConfig, available_robots, load_robot_config
from rd_pipeline.robots.model import Robot, load_pinocchio_model, load_robot

__all__ = ["Robot", "RobotConfig", "available_robots", "load_pinocchio_model", "load_robot", "load_robot_config"]
