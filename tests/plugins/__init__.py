"""One small plug-in of each kind, written as a user would write one (``docs/DESIGN.md``,
section 4): each is one module that registers itself when imported (tests/test_plugins.py)."""
