"""``python -m oasis_torchrl``: the ``oasis-torchrl`` console script."""

from oasis_torchrl.cli import main

if __name__ == "__main__":
    raise SystemExit(main())
