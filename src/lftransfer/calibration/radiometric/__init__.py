"""Radiometric calibration of the light field interface (paper, section 4.2, its "future work").

Geometry (lens array pose, lenslet intrinsics, projector-camera mapping) comes from the other calibration steps
and is passed in as a :class:`~lftransfer.rig.model.RigModel`; this module finds the device radiometry that goes
into the model's :class:`~lftransfer.lightfield.CameraModel` and :class:`~lftransfer.lightfield.ProjectorModel`:

- camera: response (a power law per channel, ``code = signal^(1/gamma)``), vignetting, exposure;
- projector: response (``drive = code^gamma`` per channel), colour cross-talk ``C`` (3 x 3), black level ``b``
  and brightness ``max_radiance``: a pixel with codes n emits ``max_radiance * (b + C @ (n / levels)^gamma)``.

It uses only what the pipeline may know: the rig file's nominal values, the (geometrically calibrated) model
passed in, the scene's view camera, and images from two calibration actions of the rig:
a :class:`~lftransfer.rig.requests.FocalPlaneDiffuser` set-up (a diffuser at the lenslets' focal plane: the LF
camera sees the projector's pixels directly; LF captures with exposure bracketing) and a
:class:`~lftransfer.rig.requests.Board` set-up (the view camera's absolute radiance image of a grey diffuse board of
known albedo lit through the array by the projector; the view camera is the radiometric reference).

Procedure (:func:`calibrate_radiometry`):

a. **Camera response.** The projector shows a grey horizontal ramp of codes (dark to bright); the focal plane
   is captured at several exposure times ``e`` (factors of 2 apart). A pixel's code is
   ``c = (s e)^(1/gamma)``, so ``log c`` against ``log e`` has slope ``1/gamma`` wherever the pixel is neither
   dark nor saturated (codes in [0.04, 0.95] of full scale are used). Per pixel and channel a weighted
   regression gives a slope; the median over pixels, then the pooled slope over the pixels near it (outliers
   out), gives ``gamma`` per channel.
b. **Camera vignetting.** A uniform full-code projector image on the diffuser (exposure chosen from (a) so that
   nothing saturates) is linearised with (a); each channel is divided by its median, the channels are averaged,
   and a 2-D polynomial (degree 4 in normalised pixel coordinates) is fitted by least squares with outlier
   rejection. The map is the polynomial normalised to 1 at its maximum over the fitted area (its absolute scale
   belongs to the exposure); pixels outside the area the projector covers get the polynomial's value too. The
   flat field holds the projector's own non-uniformity (and the diffuser's) as well, if any: the simulated rig
   has none; on hardware it would show up as vignetting.
c. **Projector response, black level, cross-talk.** Uniform projector images at the same exposure: all channels
   at code 0 (black, at a longer exposure for precision), then per projector channel j a ramp of levels with the
   other channels at 0. The camera signal, linearised by (a), divided by the vignetting and averaged over a
   central region, is ``S(n, j) = G (b + C[:, j] r_j(n))`` with an unknown common gain G (diffuser x
   exposure x max_radiance). With ``D = S - S(black) = G C[:, j] r_j(n)``, a separable least-squares fit per
   projector channel gives ``gamma_j`` (``r_j(n) = (n / levels)^gamma_j``) and the column ``G C[:, j]``. C is
   known up to scale only: it is normalised so that the mean of its diagonal is 1, and the black level is
   expressed on that same scale (``b = S(black) / s`` with s the mean diagonal of ``G C``).
d. **Absolute scale.** (i) Projector: a board asked for with a uniform full-code projector image, the board
   (0.2 m square, albedo 0.8) on the array's axis 0.1-0.2 m in front of it (the farthest of a few distances
   whose centre the view camera sees well), turned half-way between the array and the view camera. The same
   view camera pixels around the board centre are rendered with our own renderer
   (:class:`~lftransfer.render.renderer.HalfSpaceRenderer`, the board as a rectangle) lit by the light field
   that the calibrated projector model emits at ``max_radiance = 1`` (:class:`~lftransfer.render.lights.
   LightFieldLight`, area model, as the simulated rig does). The ratio of measured to predicted radiance is
   ``max_radiance``. (ii) Camera exposure: no available action measures it (the focal-plane captures give only
   the product diffuser transmission x exposure, kept in the diagnostics as ``exposure_times_diffuser``), so it
   stays at the value of the model passed in (the rig file's nominal value).

Everything is vectorised; the per-pixel work runs on a strided subset of pixels where a full image is not
needed. Progress goes to an optional callback, one call per capture group.

Modules: :mod:`.procedure` (:func:`calibrate_radiometry`), :mod:`.focal_plane` (the focal-plane captures),
:mod:`.camera_response` (step a), :mod:`.vignetting` (step b), :mod:`.projector` (step c), :mod:`.brightness`
(step d), :mod:`.result` (:class:`Radiometry`, :class:`VignettingPolynomial`, :func:`response_error`),
:mod:`.common` (the error, the board's constants, code thresholds).
"""

from lftransfer.calibration.radiometric.common import BOARD_ALBEDO, BOARD_DISTANCES, RadiometryError
from lftransfer.calibration.radiometric.procedure import calibrate_radiometry
from lftransfer.calibration.radiometric.result import Radiometry, VignettingPolynomial, response_error

__all__ = ["Radiometry", "RadiometryError", "VignettingPolynomial", "calibrate_radiometry", "response_error",
           "BOARD_DISTANCES", "BOARD_ALBEDO"]
