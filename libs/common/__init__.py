"""asibot: an assistive robot stack on Zenoh. This package is libs/common."""
