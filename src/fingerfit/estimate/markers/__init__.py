"""The individual hand model from skin markers: bundle adjustment of each digit
(:mod:`.observe` the markers in the hand frame, :mod:`.start` the staged start,
:mod:`.bundle` the adjustment)."""
