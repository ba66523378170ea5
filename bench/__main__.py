import sys

from radarbench.bench.cli import main

sys.exit(main())
