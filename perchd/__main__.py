import sys

from perchd.cli import main

sys.exit(main())
