"""The defaults of ``pincal extract``'s still stretches, averaging windows and clock-offset search
(:mod:`pincal.measurements.plateaus`, :class:`~pincal.measurements.plateaus.PlateauSettings`).

Constants only, importing nothing: the command line's parser takes ``extract``'s defaults from here
without loading the extraction (numpy, scipy, rosbags).
"""

__all__ = ["STILL_TOL", "MIN_STILL_S", "TRIM_S", "MIN_SAMPLES", "MAX_SPREAD_MM", "MAX_OFFSET_S"]

#: Default joint tolerance of a still stretch, max − min over the window [rad, or m for prismatic
#: joints]: the tolerance the shipped TIAGo sessions were cut with (data/tiago_mocap/README.md, "all
#: joints within 1 mrad for >= 2 s"); 1 mrad moves a point 1 m out by 1 mm, and the averaging takes
#: the mean of both streams over the same window.
STILL_TOL = 1e-3
#: Default shortest still stretch [s] (the TIAGo sessions' 2 s).
MIN_STILL_S = 2.0
#: Default time cut from both ends of a still stretch before averaging [s]: the arm's structure
#: settles after its joints stop, and the clock offset is known only to a few milliseconds.
TRIM_S = 0.5
#: Default fewest samples of each measured topic in an averaging window: the mean of 10 has a
#: third of one sample's noise, and 10 samples give the spread a meaning.
MIN_SAMPLES = 10
#: Default largest RMS spread of the measured positions about their mean in a window [mm]: above the
#: TIAGo mocap sessions' largest marker standard deviation (0.62 mm), and above what a still arm
#: moves (1 mrad at 1 m: 1 mm peak to peak, ~0.3 mm RMS).
MAX_SPREAD_MM = 1.0
#: Default half-width of the clock-offset search about the receive-time estimate [s]: transport and
#: buffering delays differ between a joint driver and a tracker by milliseconds to a few hundred.
MAX_OFFSET_S = 1.0
