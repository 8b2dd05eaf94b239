"""Vehicle physics: EV power (paper Eq. 1), LFP battery wear (Eq. 2-3), one priced step (Eq. 4), every parameter."""
