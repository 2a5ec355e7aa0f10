"""Hypothesis profiles: repeatable by default, exploring on request.

``make test`` (and CI) use ``repeatable``: examples are derived from each test's own
source, so the same commit passes or fails the same way every time. ``make explore``
(``HYPOTHESIS_PROFILE=explore``) draws fresh random examples (500 per test that sets no
count of its own) to hunt for new edge cases; pin any it finds as a regression test.
"""

from __future__ import annotations

import os

from hypothesis import settings

# No per-example deadline in either: timing varies on a loaded CI machine.
settings.register_profile("repeatable", derandomize=True, deadline=None, print_blob=True)
settings.register_profile("explore", max_examples=500, deadline=None, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "repeatable"))
