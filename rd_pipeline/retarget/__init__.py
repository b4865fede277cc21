"""Retargeting human motion to a robot: scaled keypoint targets, foot contacts, IK with mink."""
