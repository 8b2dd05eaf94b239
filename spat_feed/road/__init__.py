"""Road geometry: corridor files, the paper's corridors on a real road, the OpenStreetMap import, and the DP
lookup tables for a corridor's plans (``corridors``, ``osm``, ``corridor_tables``). Imports ``timing``.
"""
