from rd_pipeline.cli.app import entry_point

entry_point()
