"""The Python API under the CLI: plan, run and read a (robot, motion) DAG; sweeps and ablations."""
