"""The tracking environment: a batch of simulated robots following a reference motion.

`tracking_env.TrackingEnv` steps the physics (`physics/`, behind one seam) and assembles its
terms from `config.EnvConfig`; the terms themselves (actions, observations, rewards,
terminations, events, curricula and the motion command) live in `mdp/`."""
