"""A user skill module that ends the interpreter when imported (hostile-input corpus)."""

import sys

sys.exit(0)
