"""Signal plans and SPaT messages (to come; see the spat_feed issue). Fixed-time lights live in advisory.signals."""
