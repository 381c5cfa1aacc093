import sys

from axdf_cli.cli.main import main

sys.exit(main())
