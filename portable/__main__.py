"""``python -m portable``: ``make check-portable`` (portable/check.py)."""

from portable.check import main

raise SystemExit(main())
