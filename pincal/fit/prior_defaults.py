"""The prior scales of ``--select prior`` (:mod:`pincal.fit.prior`): their defaults, accepted range and
the physical bounds of their estimate (:mod:`pincal.fit.prior_scales`).

Constants only, importing nothing: the command line's parser takes the defaults and the range of
``--prior-scale`` from here without loading the fit (numpy, scipy).
"""

__all__ = ["DEFAULT_TRANSLATION_MM", "DEFAULT_ROTATION_DEG", "DEFAULT_JOINT_ZERO_DEG", "SCALE_RANGE", "KINDS",
           "ESTIMATE_BOUNDS"]

#: Prior standard deviation of a translation, or of a prismatic joint's zero [mm]: where the scales are
#: not estimated, the start of their estimate, and the scales it is compared with.
DEFAULT_TRANSLATION_MM = 1.0
#: Prior standard deviation of a rotation of a joint placement [deg] (as above).
DEFAULT_ROTATION_DEG = 0.5
#: Prior standard deviation of a revolute joint's zero [deg] (as above).
DEFAULT_JOINT_ZERO_DEG = 0.5
#: Accepted range of each prior scale, inclusive (mm for translations, degrees for rotations): 1 nm to
#: 1 km and 1e-6° to 1e6°. Beyond it the prior rows outweigh the data by ~1e12 or more (σ_data² / σ²)
#: and the normal equations lose every digit (1e-300 ends in a singular-matrix error), or the
#: prior is no prior at all.
SCALE_RANGE = (1e-6, 1e6)
#: The three kinds of kinematic parameter, each with its own prior scale (:mod:`pincal.fit.prior_scales`).
KINDS = ("lengths", "angles", "joint zeros")
#: Where an estimated scale may lie, per kind (mm, deg, deg), inclusive: the physical range of a
#: robot's placement errors. Lengths: 0.01 mm, a link machined to IT6 (16–25 µm over 120–500 mm,
#: ISO 286-1) and the thermal growth of 1 m of steel over 1 K (12 µm), below which a length is not
#: defined; to 10 mm, above ISO 2768-1's coarsest class (v: ±8 mm over 2–4 m) — a larger error is a
#: wrong drawing, not a tolerance. Angles: 0.001° (17 µrad), 0.01 mm across a 0.6 m link; to 5°,
#: above ISO 2768-1 class v's ±3° for the shortest features. Joint zeros: 0.001°, a 19-bit absolute
#: encoder's count (0.0007°); to 10°, a zero set by eye on a mark or a motor turn slipped through a
#: 50:1 gear (7.2°). At a bound the estimate stops: a kind whose parameters the few rows set to zero
#: cannot collapse its prior to nothing, nor one they hardly see widen it without end.
ESTIMATE_BOUNDS = ((0.01, 10.0), (0.001, 5.0), (0.001, 10.0))
