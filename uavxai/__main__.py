import sys

from uavxai.cli import main

sys.exit(main())
