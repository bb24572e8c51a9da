"""The prior scales of ``--select prior`` (:mod:`pincal.fit.prior`): their defaults and accepted range.

Constants only, importing nothing: the command line's parser takes the defaults and the range of
``--prior-scale`` from here without loading the fit (numpy, scipy).
"""

__all__ = ["DEFAULT_TRANSLATION_MM", "DEFAULT_ROTATION_DEG", "SCALE_RANGE"]

#: Prior standard deviation of a translation, or of a prismatic joint's zero [mm].
DEFAULT_TRANSLATION_MM = 1.0
#: Prior standard deviation of a rotation, or of a revolute joint's zero [deg].
DEFAULT_ROTATION_DEG = 0.5
#: Accepted range of each prior scale, inclusive (mm for translations, degrees for rotations): 1 nm to
#: 1 km and 1e-6° to 1e6°. Beyond it the prior rows outweigh the data by ~1e12 or more (σ_data² / σ²)
#: and the normal equations lose every digit (1e-300 ends in a singular-matrix error), or the
#: prior is no prior at all.
SCALE_RANGE = (1e-6, 1e6)
