"""Observation and prediction of phase ends: a matched position and the lights' SPaT plans turned into what
the advisor sees (``observe``). Imports ``timing`` and ``road``.
"""
