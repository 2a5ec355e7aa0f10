"""Plug-ins by name: finding them among the installed entry points and modules, with where
they came from (``registry.py``)."""
