"""rd-pipeline: LAFAN1 motion capture to humanoid dance-tracking policies, as a staged DAG."""

__version__ = "0.1.0"
