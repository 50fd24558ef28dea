import sys

from hil_sim.cli import main

sys.exit(main())
