from axdf_cli.cli.main import entry

entry()
