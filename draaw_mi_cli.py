"""Entry point of the ``draaw-mi`` console script.

It lives outside the ``draaw_mi`` package so that an environment problem found while importing
the package (no usable libLLVM, a bad ``DRAAW_MI_VARIANT``) is still reported as one line with
exit status 2 instead of a traceback.
"""
from __future__ import annotations

import sys


def main(argv=None) -> int:
    try:
        from draaw_mi.cli import main as cli_main
    except Exception as e:  # noqa: BLE001
        if any(c.__name__ == "DraawError" for c in type(e).__mro__):
            print(f"draaw-mi: error: {e}", file=sys.stderr)
            return 2
        raise
    return cli_main(argv)


if __name__ == "__main__":
    sys.exit(main())
