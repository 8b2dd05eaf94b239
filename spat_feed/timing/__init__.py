"""Signal timing models and J2735 messages: what a light does and how it is said, with no road and no clock.

``plans`` (fixed-time and uncertain plans, pure schedules), ``timemark`` (J2735 TimeMark arithmetic),
``messages`` (the SPaT JSON schema and J2735 conversion), ``paper`` (the paper's timings relative to a
trip's zone entry) and ``signal_plans`` (signal-plan files: timings by time of day). The bottom layer of
``spat_feed``: it imports no other subpackage at run time.
"""
