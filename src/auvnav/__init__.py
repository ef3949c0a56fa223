"""auvnav: consistent navigation for survey AUVs with cheap navigation."""

__version__ = "0.3.0"
