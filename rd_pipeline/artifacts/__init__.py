"""Artifacts and the DAG: content keys, the atomic store, stage specs and the runner."""
