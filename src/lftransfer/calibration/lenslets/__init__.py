"""Lenslet centres from a spot image (collimated on-axis source) or a white image, and the lattice through them.

Two kinds of calibration image are understood (``kind=`` of :func:`find_lenslet_centres`):

* ``"spots"``: a collimated on-axis source seen through the lens array. Every lenslet focuses the plane wave
  into one small spot at the image of its optical centre (see the simulated rig's ``Collimator`` set-up);
  the spot's centroid is the lenslet's centre.
* ``"white"``: a uniformly lit diffuser in front of the array (the usual light-field camera calibration
  image). Every lenslet's sub-image is a bright blob about one pitch wide (the footprint of its aperture, a
  disk or hexagon with a soft, vignetted fall-off towards its edge), touching or nearly touching its
  neighbours, the whole image dimmer towards the corners (main-lens vignetting). The sub-image's centre of
  symmetry is the image of the chief ray through the lenslet's centre. For our rig, where the camera images
  the lenslets' focal plane telecentrically, that chief ray is parallel to the axis, so the white image's
  sub-image centres coincide with the on-axis collimated spots of a spot image (in a light-field camera
  whose main lens is not telecentric they are the spots of a source at the main lens' exit pupil instead).

:func:`find_lenslet_centres` finds those centres to a small fraction of a pixel and fits the lattice to them
(``lft calibrate lenslets IMAGE --lattice hex --out centres.csv``):

1. spots (``"spots"``):

   a. background: the median of 16 or 32 pixel blocks, interpolated, is subtracted (follows vignetting and an
      uneven dark background); later passes leave the bright pixels of the previous one out, so that dense
      spots do not raise it. Hot pixels (a single pixel far above its 3 x 3 median) are replaced by that
      median. The noise is measured on what is left, without the spots, on the lower half of the
      distribution (the upper half where the dark background was clipped at zero);
   b. detection: local maxima of the lightly smoothed image above 5 noise sigmas, above 10 % of the brightest
      spot within two pitches and above 5 % of the bright spots (95th percentile) anywhere (dim vignetted
      border spots are kept, noise maxima are not); spots whose centre lies within ``2.5 sigma`` (at least
      2 px) of the image border are dropped (clipped spots);
   c. sub-pixel centres: Gaussian-windowed centroid (the window's sigma is the spots' own, estimated from the
      brightest spots), iterated to its fixed point on the background-subtracted image, after subtracting
      each spot's local background (median of a ring around it);

2. sub-images (``"white"``):

   a. pitch: the nearest peak of the image's autocorrelation (central crop, high-passed, Hann-windowed);
   b. detection: the image is divided by its vignetting envelope (a Gaussian blur of about one pitch, which
      wipes out the lattice's period), smoothed with a Gaussian of a fifth of the pitch (each sub-image
      becomes one peak near its centre), and its local maxima (one per 0.7 pitch) that stand out from their
      surroundings (at least 30 % of the typical peak's contrast, where the envelope is above 10 % of its
      top) are the sub-images;
   c. sub-pixel centres: centroid of the image within a flat, centrally symmetric window (2 px soft edge),
      iterated to its fixed point: the sub-image's centre of symmetry. A first pass uses a disk of radius
      half the pitch. The main lens' vignetting tilts each sub-image (a bias of ``gradient * radius^2 / 4``,
      a few hundredths of a pixel, towards the image centre), so each sub-image's relative brightness gradient
      is measured from its neighbours' mean brightnesses (a plane fitted to those within 2.3 pitches) and
      divided out of its window in a second pass. That pass's window follows the distorted lattice: a disk of
      half the local pitch for sub-images apart from each other, or, for touching ones (whose radial profile
      does not fall to a dark gap within half a pitch), the sub-image's own lattice cell (hexagon or
      rectangle through the midpoints to its neighbours, 1 px in, symmetrised), so that no neighbour, nearer
      on one side than on the other where the pitch changes, reaches into it. Near the image border the window
      is cut by a disk that stays inside the image, down to the sub-image's extent. Sub-images darker than
      75 % of their neighbours (cut by the edge of the lit area) and those cut by the image border are
      dropped;

3. lattice (both kinds): pitch from nearest-neighbour distances, rotation from the neighbours' directions
   (modulo 60 deg for ``hex``, 90 deg for ``rect``). Integer indices are assigned by growing the lattice from
   the detection nearest the middle outwards: each unassigned detection within 2.2 pitches of assigned ones
   is predicted in lattice coordinates from up to four assigned neighbours through their local lattice
   Jacobians (local affine fits of the assigned nodes within 2.6 pitches), and takes the nearest node if all
   predictions agree on it (within 0.3 of a pitch for the mean, 0.4 for each) and no detection holds it
   yet. The growth follows any smooth distortion (a main lens' barrel or pincushion distortion of several
   pitches at the corners), which a global homography does not;
4. lattice model: a homography from the ideal lattice to undistorted pixels, followed by radial distortion
   about a fitted centre,

   ``p = c + (q - c) (1 + k1 rho^2 + k2 rho^4)``, ``q = H (u, v, 1)``, ``rho = |q - c| / s``,

   with ``s`` the image's half-diagonal (``c`` is held near the image centre by a weak prior, which only
   matters while the distortion is too weak to locate it). It is fitted by least squares to the grown
   detections (Levenberg-Marquardt, from the least-squares homography); detections a quarter pitch or more
   off it, or farther from it than 8 robust sigmas of the residuals and 0.2 px (a disturbed spot or a cut
   sub-image), are dropped, refitting until none is; detections the growth did not reach are assigned
   through the model's inverse, and the model is refitted to all. The radial terms are kept only if they
   explain significantly more than noise (F-test of the two fits, F > 10, and the RMS down by 2 % or more);
   otherwise ``k1 = k2 = 0`` and the model is the least-squares homography, as for an undistorted image.
   ``LatticeFit.rms_px`` is the residual of that model; ``LatticeFit.homography_rms_px`` that of the best
   homography alone, for comparison.

Conventions:

* pixel coordinates ``(x, y)`` = (col, row), origin at the centre of the top-left pixel, y down;
* lattice indices ``(row, col)``: the rows run along the lattice direction closest to the image x axis, row
  indices grow downwards in the image and column indices to the right; the top detected row is row 0 and
  the leftmost detected lenslet is in column 0;
* ideal lattice coordinates (unit pitch) of index ``(r, c)``: ``u = c + (r % 2) / 2`` for ``hex`` (odd rows
  shifted by half a pitch towards +x, like ``LensArray``), ``u = c`` for ``rect``; ``v = r sqrt(3) / 2`` for
  ``hex``, ``v = r`` for ``rect``. For ``hex``, column 0 is the leftmost node over all rows in that
  convention: if the top detected row is shifted right of the row below it, its first lenslet is in column 1
  and the row below starts at column 0 (then the top detected row is an odd row of the physical array, e.g.
  row 0 clipped off; pass ``expected_shape`` to have the indices match the array's in that case).

Modules: :mod:`.spots` (step 1), :mod:`.white` (step 2), :mod:`.lattice` (step 3), :mod:`.model` (step 4),
:mod:`.fit` (the result, :class:`LatticeFit`), :mod:`.procedure` (:func:`find_lenslet_centres`,
:func:`write_centres_csv`), :mod:`.common` (the error, :func:`lattice_coordinates`, checks).
"""

from lftransfer.calibration.lenslets.common import NoSpotsError, lattice_coordinates
from lftransfer.calibration.lenslets.fit import LatticeFit
from lftransfer.calibration.lenslets.procedure import find_lenslet_centres, write_centres_csv

__all__ = ["LatticeFit", "NoSpotsError", "find_lenslet_centres", "lattice_coordinates", "write_centres_csv"]
