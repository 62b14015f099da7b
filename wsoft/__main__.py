import sys

from wsoft.cli import main

sys.exit(main())
