from rd_pipeline.cli import entry_point

entry_point()
