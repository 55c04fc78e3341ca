"""The round strategies of :func:`jaxlimb.pipeline.locate`: a sphere measured on its lit limb (Aerospace 2015 §4-6,
Mortari et al. 2016 §V-C), a self-luminous limb-darkened disc (the Sun), and a sphere whose limb the hints
predict, measured on its whole limb or on the visible arc of a body larger than the frame.

Modules: :mod:`.body` (the sphere and disc strategies), :mod:`.annulus` (the lit limb's pixels), :mod:`.fits` (the
sigmoid fits on them), :mod:`.edge` (the edge-fit stage and its checks), :mod:`.refit` (the profile refit),
:mod:`.center` (the exact sphere map), :mod:`.dark_limb` (the dark-limb check), :mod:`.sun` (the limb-darkened
disc); :mod:`.predicted` (the predicted-limb strategy), :mod:`.whole_limb` and :mod:`.polarity_split` (its fits).
"""

from .body import Disc as Disc, Sphere as Sphere
from .predicted import PredictedLimbSphere as PredictedLimbSphere

__all__ = ["Disc", "PredictedLimbSphere", "Sphere"]
