"""Observation and prediction of phase ends, in layers: what each signal group has been seen to do, learnt reading
by reading (``history``); when its phases end, as a distribution from that past (``predictor``); a matched position
and the lights' SPaT plans turned into what the advisor sees (``observe``); and the oracle forecasts that evaluation
compares the predictor with (``oracle``). Imports ``timing`` and ``road``.
"""
