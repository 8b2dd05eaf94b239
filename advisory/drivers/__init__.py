"""Drivers: the paper's regular driver and the virtual driver who follows the advice (closed loop)."""
