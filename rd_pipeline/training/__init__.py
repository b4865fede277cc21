"""Training a policy on the tracking environment: the runner (build, learn, resume, grow, score),
its loop and checkpoints, multi-head PPO on rsl-rl-lib, the distributed launch and the log."""
