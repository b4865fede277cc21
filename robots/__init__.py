"""Robot configurations (`<robot>.toml`), installed as package data of `rd_pipeline.robot_configs`."""
