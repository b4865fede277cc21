"""Residual-action tracking RL: actions, rewards, the multi-head advantage, the physics backend."""
