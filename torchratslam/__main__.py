import sys

from torchratslam.cli import main

sys.exit(main())
