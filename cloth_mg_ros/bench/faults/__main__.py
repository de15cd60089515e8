"""`python -m cloth_mg_ros.bench.faults`: `cloth-mg bench faults` on its own."""

import sys

from cloth_mg_ros.bench.faults import main

sys.exit(main())
