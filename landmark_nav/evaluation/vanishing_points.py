"""Vanishing-point accuracy on the York Urban database (angular error of directions).

The data (``../shared/data/york_urban_train/``, Denis, Elder, Estrada, ECCV 2008): per image
``NAME.jpg`` (640 x 480) and ``NAME_gt.npz`` with ``vp`` (3 x 3, one unit direction per
column in the dataset's camera frame, y up), hand-labelled ``lines`` and their
``vp_association``. One camera for all images: f = 674.917 px, principal point
(307.551, 251.454) px, no distortion given. The dataset's pixel VP of column ``d`` is
``K diag(1, -1, 1) d``, so ``diag(1, -1, 1) d`` is the direction in our optical frame
(x right, y down, z forward).

Metrics (angles between axial directions, ``acos |a . b|``, in degrees):

* ``axis``: for the ground-truth direction closest to the optical axis (largest
  ``|d_z|``), the error of the detected direction matched to it (one-to-one assignment of
  the detected to the true directions minimising the summed error, ``scipy``'s
  ``linear_sum_assignment``); for a single-VP method, the error of its one VP.
* ``axis_selected``: the error of the detected direction *we* would call the corridor
  direction (the detected one closest to the optical axis) against the same truth; differs
  from ``axis`` when two directions are about equally far from the axis, as in many
  outdoor York images (never in a corridor seen along its axis).
* ``all``: the matched errors of all three true directions (90 deg for one with no
  detected partner), as the Manhattan-frame literature reports them.
"""

from dataclasses import dataclass, replace
from pathlib import Path
import time
from typing import Callable, Dict, List, Optional, Sequence, Tuple, Union

import cv2
from landmark_nav.corridor.vanishing_point import (chapter_vanishing_point, manhattan_frame,
                                                   residual_terms,
                                                   VPParams)
from landmark_nav.corridor.vp_confidence import (assess_direction, assess_frame, CORRECT_DEG,
                                                 fit_calibration, VPCalibration)
from landmark_nav.vision.image_lines import detect_lines, ImageLines, LineParams
import numpy as np

#: York Urban intrinsics (its README): f = 6.05317 mm / 0.00896875 mm per pixel.
YORK_K = np.array([[674.917, 0.0, 307.551], [0.0, 674.917, 251.454], [0.0, 0.0, 1.0]])
#: The dataset's camera y axis points up; ours down.
YORK_FLIP = np.diag([1.0, -1.0, 1.0])
#: Detectors evaluated: name -> (line method, VP method).
DETECTORS = ('manhattan', 'chapter')


@dataclass(frozen=True, eq=False)
class YorkImage:
    """One York Urban image with its ground truth in our optical frame."""

    name: str
    image_path: Path
    directions: np.ndarray      # (3, 3) unit columns, optical frame
    lines: np.ndarray           # (N, 4) hand-labelled segments [px]
    association: np.ndarray     # (N,) column index 0..2 of each labelled segment

    @property
    def axis_index(self) -> int:
        """Column of the true direction closest to the optical axis."""
        return int(np.argmax(np.abs(self.directions[2])))


def load_york_urban(root: Union[str, Path]) -> List[YorkImage]:
    """Return the images of a York Urban folder (``NAME.jpg`` + ``NAME_gt.npz``), sorted.

    Raises:
        FileNotFoundError: the folder has no ``*_gt.npz`` or an image is missing.
        ValueError: a ground-truth file lacks a key or has a wrong shape (names the file).
    """
    root = Path(root)
    gts = sorted(root.glob('*_gt.npz'))
    if not gts:
        raise FileNotFoundError(f'{root}: no *_gt.npz ground-truth files')
    out = []
    for gt in gts:
        name = gt.name[:-len('_gt.npz')]
        img = root / f'{name}.jpg'
        if not img.exists():
            raise FileNotFoundError(f'{gt}: image {img.name} is missing')
        with np.load(gt) as z:
            for key in ('vp', 'lines', 'vp_association'):
                if key not in z:
                    raise ValueError(f'{gt}: missing key {key!r}')
            vp = np.asarray(z['vp'], dtype=float)
            lines = np.asarray(z['lines'], dtype=float).reshape(-1, 4)
            assoc = np.asarray(z['vp_association']).reshape(-1).astype(int) - 1
        if vp.shape != (3, 3) or not np.all(np.isfinite(vp)):
            raise ValueError(f'{gt}: vp must be a finite 3 x 3 array; got {vp.shape}')
        d = YORK_FLIP @ vp
        d /= np.linalg.norm(d, axis=0, keepdims=True)
        out.append(YorkImage(name, img, d, lines, assoc))
    return out


def angular_error_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Return the angle [deg] between two axial directions (sign-free)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    c = abs(float(a @ b)) / (np.linalg.norm(a) * np.linalg.norm(b))
    return float(np.degrees(np.arccos(min(1.0, c))))


def matched_errors(detected: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Return, per true direction (columns of ``truth``), the error of its matched detection.

    Args:
        detected: (3, k) detected unit directions, k >= 0.
        truth: (3, m) true unit directions.

    Returns:
        (m,) errors [deg] under the one-to-one assignment minimising their sum; 90 deg for a
        true direction left without a partner.
    """
    detected = np.asarray(detected, dtype=float).reshape(3, -1)
    truth = np.asarray(truth, dtype=float).reshape(3, -1)
    out = np.full(truth.shape[1], 90.0)
    if detected.shape[1] == 0:
        return out
    cost = np.array([[angular_error_deg(detected[:, i], truth[:, j])
                      for j in range(truth.shape[1])] for i in range(detected.shape[1])])
    from scipy.optimize import linear_sum_assignment  # here: scipy.optimize takes 0.35 s to import
    r, c = linear_sum_assignment(cost)
    out[c] = cost[r, c]
    return out


@dataclass(frozen=True)
class FrameResult:
    """Errors [deg] and times [s] of one image."""

    name: str
    axis: float
    axis_selected: float
    all_three: Tuple[float, float, float]
    n_lines: int
    t_lines: float
    t_vp: float


def scaled_camera(K: np.ndarray, factor: float) -> np.ndarray:
    """Return K of an image resized by ``factor`` (pixel centres at integer coordinates)."""
    S = np.array([[factor, 0.0, 0.5 * factor - 0.5], [0.0, factor, 0.5 * factor - 0.5],
                  [0.0, 0.0, 1.0]])
    return S @ K


def _load_scaled(item: YorkImage, scale: float) -> Tuple[np.ndarray, np.ndarray]:
    """Return the grey image resized by ``scale`` (INTER_AREA) and its K."""
    img = cv2.imread(str(item.image_path), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise ValueError(f'{item.image_path}: cannot read the image')
    if scale == 1.0:
        return img, YORK_K
    img = cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    return img, scaled_camera(YORK_K, scale)


def evaluate_image(item: YorkImage, line_method: str = 'segmented_hough',
                   detector: str = 'manhattan', scale: float = 1.0,
                   line_params: LineParams = LineParams(),
                   vp_params: VPParams = VPParams(),
                   clock: Callable[[], float] = time.perf_counter) -> FrameResult:
    """Detect lines and vanishing directions on one image and score them.

    Args:
        item: the image and its truth.
        line_method: one of :data:`landmark_nav.vision.image_lines.METHODS`.
        detector: ``'manhattan'`` (:func:`manhattan_frame`) or ``'chapter'``
            (:func:`chapter_vanishing_point`, one VP).
        scale: resize factor of the image before detection (0.5: 320 x 240).
        line_params: line detector parameters.
        vp_params: VP parameters (the same pixel noise at every image size: quantisation
            and edge localisation are per pixel).
        clock: time source for the two stage times.

    Raises:
        ValueError: unknown detector, or an unreadable image (names the file).
    """
    if detector not in DETECTORS:
        raise ValueError(f'unknown detector {detector!r}; expected one of {DETECTORS}')
    img, K = _load_scaled(item, scale)
    t0 = clock()
    lines = detect_lines(img, line_method, line_params)
    t1 = clock()
    truth = item.directions
    ax = item.axis_index
    try:
        if detector == 'manhattan':
            frame = manhattan_frame(lines.segments, K, lines.weights, vp_params)
            found = frame.directions
        else:
            found = chapter_vanishing_point(lines.segments, K, vp_params).direction[:, None]
    except ValueError:
        found = np.zeros((3, 0))
    t2 = clock()
    errs = matched_errors(found, truth)
    if found.shape[1] == 0:
        selected = 90.0
    else:
        sel = int(np.argmax(np.abs(found[2])))
        selected = angular_error_deg(found[:, sel], truth[:, ax])
    axis = errs[ax] if detector == 'manhattan' else selected
    return FrameResult(item.name, float(axis), float(selected), tuple(float(e) for e in errs),
                       len(lines), t1 - t0, t2 - t1)


def summarize(results: List[FrameResult]) -> Dict[str, float]:
    """Return the summary figures of a run (medians in deg, fractions in [0, 1], times in s)."""
    axis = np.array([r.axis for r in results])
    sel = np.array([r.axis_selected for r in results])
    all3 = np.array([r.all_three for r in results]).reshape(-1)
    t = np.array([r.t_lines + r.t_vp for r in results])
    return {
        'images': float(len(results)),
        'axis_median': float(np.median(axis)),
        'axis_within_2deg': float(np.mean(axis <= 2.0)),
        'axis_selected_median': float(np.median(sel)),
        'axis_selected_within_2deg': float(np.mean(sel <= 2.0)),
        'all_median': float(np.median(all3)),
        'all_within_2deg': float(np.mean(all3 <= 2.0)),
        'time_median': float(np.median(t)),
        'time_lines_median': float(np.median([r.t_lines for r in results])),
    }


def evaluate_york(root: Union[str, Path], line_method: str = 'segmented_hough',
                  detector: str = 'manhattan', scale: float = 1.0) -> List[FrameResult]:
    """Score every image of a York Urban folder (see :func:`evaluate_image`)."""
    return [evaluate_image(item, line_method, detector, scale)
            for item in load_york_urban(root)]


# ----------------------------------------------------------------------------- confidence
@dataclass(frozen=True)
class DirectionSample:
    """One detected Manhattan direction with its confidence features and true error.

    ``column`` 0 is the detected direction closest to the optical axis (the corridor
    direction); ``error`` [deg] is against the true direction matched to it (one-to-one
    assignment, :func:`matched_errors`); ``true_axis``: that true direction is the one
    closest to the optical axis.
    """

    image: str
    scale: float
    column: int
    sigma_cov: float
    sigma_frame: float
    ambiguity: float
    focal_px: float
    orthogonality: float
    influence: float
    inliers: int
    log10_nfa: float
    error: float
    true_axis: bool


def image_lines(item: YorkImage, scale: float = 1.0, line_method: str = 'segmented_hough'
                ) -> Tuple[ImageLines, np.ndarray]:
    """Return the line segments of one image resized by ``scale`` and the image's K."""
    img, K = _load_scaled(item, scale)
    return detect_lines(img, line_method), K


def confidence_samples(item: YorkImage, scale: float = 1.0,
                       line_method: str = 'segmented_hough',
                       vp_params: VPParams = VPParams(),
                       lines: Optional[Tuple[ImageLines, np.ndarray]] = None
                       ) -> List[DirectionSample]:
    """Return the three detected directions of one image with their features and errors.

    ``lines``: the image's ``(lines, K)`` from :func:`image_lines` at ``scale`` (detected
    here when None). ``true_axis`` marks the sample matched to the true direction closest
    to the optical axis (its error is :class:`FrameResult`'s ``axis``).
    """
    lines, K = image_lines(item, scale, line_method) if lines is None else lines
    frame = manhattan_frame(lines.segments, K, lines.weights, vp_params)
    conf = assess_frame(frame, lines.segments, K, vp_params.sigma_px, gate=vp_params.gate,
                        sigma_angle_deg=vp_params.sigma_angle_deg)
    D = frame.directions
    cost = np.array([[angular_error_deg(D[:, i], item.directions[:, j]) for j in range(3)]
                     for i in range(3)])
    from scipy.optimize import linear_sum_assignment  # here: scipy.optimize takes 0.35 s to import
    r, c = linear_sum_assignment(cost)
    focal = float(np.sqrt(K[0, 0] * K[1, 1]))
    return [DirectionSample(item.name, scale, k, conf[k].sigma_cov, conf[k].sigma_frame,
                            conf[k].ambiguity, focal, conf[k].orthogonality,
                            conf[k].influence, conf[k].inliers, conf[k].log10_nfa,
                            float(cost[k, c[list(r).index(k)]]),
                            c[list(r).index(k)] == item.axis_index)
            for k in range(3)]


@dataclass(frozen=True)
class HeldOut:
    """A direction scored by a calibration fitted without its image."""

    sample: DirectionSample
    fold: int
    p_correct: float
    radius95_deg: float
    confident: bool


def calibrate(samples: Sequence[DirectionSample], orthogonality: bool = True,
              influence: bool = True) -> VPCalibration:
    """Fit the confidence model on samples (:func:`~.vp_confidence.fit_calibration`).

    All directions fit the correct mode's spread and the wrong mode's; the logistic weights
    and the confidence threshold are fitted on the corridor directions (column 0).
    ``orthogonality``: the orthogonality residual is the model's fifth feature and, with
    ``influence``, the influence its sixth (as in :data:`~.vp_confidence.CALIBRATION`);
    ``influence`` False: the five-feature model; ``orthogonality`` False: the four-feature
    model.
    """
    return fit_calibration([s.sigma_cov for s in samples], [s.sigma_frame for s in samples],
                           [s.focal_px for s in samples],
                           [s.inliers for s in samples],
                           [s.log10_nfa for s in samples], [s.error for s in samples],
                           threshold_on=[s.column == 0 for s in samples],
                           orthogonality=([s.orthogonality for s in samples]
                                          if orthogonality else None),
                           influence=([s.influence for s in samples]
                                      if orthogonality and influence else None))


def image_folds(names: Sequence[str], folds: int = 5) -> Dict[str, int]:
    """Return the fold of each image: in name order, image ``i`` to fold ``i mod folds``."""
    return {n: i % folds for i, n in enumerate(sorted(set(names)))}


def _held_out(samples: Sequence[DirectionSample], fold: int, cal: VPCalibration
              ) -> List[HeldOut]:
    """Return ``samples`` (one fold's) scored by a calibration fitted without them."""
    out = []
    for s in samples:
        p, _, r95 = assess_direction(s.sigma_cov, s.sigma_frame, s.focal_px, s.inliers,
                                     s.log10_nfa, cal, s.orthogonality, s.influence)
        out.append(HeldOut(s, fold, p, float(np.degrees(r95)), p >= cal.p_confident))
    return out


def cross_validate(samples: Sequence[DirectionSample], folds: int = 5,
                   orthogonality: bool = True, influence: bool = True
                   ) -> Tuple[List[HeldOut], List[VPCalibration]]:
    """Score every sample with a calibration fitted on the other folds of images.

    Images are dealt to the folds by :func:`image_folds`; all sizes and directions of an
    image stay in its fold. The samples' segment noise is the same for every fold (see
    :func:`cross_validate_noise` for noise fitted per fold). ``orthogonality``,
    ``influence``: as :func:`calibrate`.
    """
    fold_of = image_folds([s.image for s in samples], folds)
    out, cals = [], []
    for f in range(folds):
        cal = calibrate([s for s in samples if fold_of[s.image] != f], orthogonality,
                        influence)
        cals.append(cal)
        out += _held_out([s for s in samples if fold_of[s.image] == f], f, cal)
    return out, cals


@dataclass(frozen=True)
class FoldNoise:
    """The segment noise fitted on one fold's training images (:func:`segment_noise`)."""

    sigma_px: float
    sigma_angle_deg: float
    segments: int


def cross_validate_noise(items: Sequence[YorkImage], scales: Sequence[float] = (1.0, 0.5),
                         vp_params: VPParams = VPParams(), folds: int = 5,
                         line_method: str = 'segmented_hough',
                         noise_scale: Optional[float] = 1.0, per_size: bool = False,
                         orthogonality: bool = True, influence: bool = True
                         ) -> Tuple[List[HeldOut], List[Dict[float, VPCalibration]],
                                    List[Dict[float, FoldNoise]]]:
    """Held-out directions with the segment noise *and* the confidence fitted per fold.

    For each fold of images (:func:`image_folds`): the segment noise ``(sigma_px,
    sigma_angle_deg)`` is fitted on the other folds' images at ``noise_scale``
    (:func:`segment_noise`, as ``VPParams``' defaults were fitted on all images at 640 x
    480), or, with ``noise_scale=None``, at each size in ``scales`` for the images of that
    size; every image is estimated at every size in ``scales`` with that noise; the
    confidence model is fitted on the other folds' directions (:func:`calibrate`; with
    ``per_size``, one model per size on that size's directions) and applies to the fold's
    own (with ``orthogonality`` and ``influence`` as :func:`calibrate`). The segments the
    noise is fitted on are labelled with ``vp_params.sigma_px`` and no direction noise (as
    ``segment_noise`` is used for the defaults); apart from that labelling constant nothing
    of a held-out image enters its estimate's constants. Lines are detected once per image
    and size (the noise changes only the Manhattan search).

    Returns:
        ``(held-out directions, calibration per fold and size, noise per fold and size)``.
    """
    names = [it.name for it in items]
    fold_of = image_folds(names, folds)
    noise_at = {sc: sc if noise_scale is None else noise_scale for sc in scales}
    lines = {(it.name, sc): image_lines(it, sc, line_method)
             for sc in sorted(set(scales) | set(noise_at.values())) for it in items}
    label = replace(vp_params, sigma_angle_deg=0.0)
    residuals = {(it.name, ns): segment_residuals(it, ns, label, line_method, lines[it.name, ns])
                 for ns in set(noise_at.values()) for it in items}
    out, cals, noises = [], [], []
    for f in range(folds):
        train = [n for n in names if fold_of[n] != f]
        fitted = {}
        for ns in sorted(set(noise_at.values()), reverse=True):
            sp, sa, kept = fit_segment_noise(*(np.concatenate(
                [residuals[n, ns][i] for n in train]) for i in range(3)))
            fitted[ns] = FoldNoise(sp, sa, kept)
        noises.append({sc: fitted[noise_at[sc]] for sc in scales})
        samples = [s for sc in scales for it in items
                   for s in confidence_samples(it, sc, line_method, replace(
                       vp_params, sigma_px=noises[f][sc].sigma_px,
                       sigma_angle_deg=noises[f][sc].sigma_angle_deg), lines[it.name, sc])]
        groups = {sc: [sc] for sc in scales} if per_size else {None: list(scales)}
        cal_f = {}
        for group in groups.values():
            cal = calibrate([s for s in samples if fold_of[s.image] != f and s.scale in group],
                            orthogonality, influence)
            cal_f.update({sc: cal for sc in group})
            out += _held_out([s for s in samples if fold_of[s.image] == f and s.scale in group],
                             f, cal)
        cals.append(cal_f)
    return out, cals, noises


def accuracy_summary(held: Sequence[HeldOut]) -> Dict[str, float]:
    """Return the accuracy of held-out directions as :func:`summarize` names it [deg, 0-1].

    ``axis_*``: the detection matched to each image's true direction closest to the
    optical axis; ``all_median``: the median over all three matched directions.

    Raises:
        ValueError: No held-out direction matched to an image's axis direction.
    """
    axis = np.array([h.sample.error for h in held if h.sample.true_axis])
    every = np.array([h.sample.error for h in held])
    if axis.size == 0:
        raise ValueError(f'accuracy_summary: no axis direction among {len(held)} held-out '
                         'directions (no image estimated?)')
    return {'images': float(axis.size), 'axis_median': float(np.median(axis)),
            'axis_within_2deg': float(np.mean(axis <= CORRECT_DEG)),
            'all_median': float(np.median(every))}


def confidence_summary(held: Sequence[HeldOut]) -> Dict[str, float]:
    """Return the acceptance figures of held-out directions (fractions in [0, 1]).

    ``axis_*``: the corridor direction (column 0) of each image; ``all_*``: every direction.
    ``*_confident``: fraction reported confident; ``*_precision``: fraction within 2 deg
    among those (nan when none); ``*_coverage``: fraction whose 95 % radius covers the error.
    """
    out = {}
    for key, rows in (('axis', [h for h in held if h.sample.column == 0]), ('all', held)):
        conf = [h for h in rows if h.confident]
        out[f'{key}_n'] = float(len(rows))
        out[f'{key}_confident'] = len(conf) / max(len(rows), 1)
        out[f'{key}_precision'] = (float(np.mean([h.sample.error <= CORRECT_DEG for h in conf]))
                                   if conf else float('nan'))
        out[f'{key}_coverage'] = float(np.mean([h.sample.error <= h.radius95_deg
                                                for h in rows]))
        out[f'{key}_within_2deg'] = float(np.mean([h.sample.error <= CORRECT_DEG
                                                   for h in rows]))
    return out


# ----------------------------------------------------------------------------- line noise
def segment_residuals(item: YorkImage, scale: float = 1.0, vp_params: VPParams = VPParams(),
                      line_method: str = 'segmented_hough',
                      lines: Optional[Tuple[ImageLines, np.ndarray]] = None
                      ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(r, a, b)`` of one image's labelled segments against its true directions.

    The segments labelled by :func:`manhattan_frame` (with ``vp_params``) are scored
    against the true direction matched to their label
    (:func:`~landmark_nav.corridor.vanishing_point.residual_terms`). ``lines``: as for
    :func:`confidence_samples`.
    """
    from scipy.optimize import linear_sum_assignment
    lines, K = image_lines(item, scale, line_method) if lines is None else lines
    frame = manhattan_frame(lines.segments, K, lines.weights, vp_params)
    cost = np.array([[angular_error_deg(frame.directions[:, i], item.directions[:, j])
                      for j in range(3)] for i in range(3)])
    rs, As, Bs = [np.zeros(0)], [np.zeros(0)], [np.zeros(0)]
    for k, j in zip(*linear_sum_assignment(cost)):
        mask = frame.labels == k
        if np.any(mask):
            r, a, b = residual_terms(lines.segments[mask], K, item.directions[:, j])
            rs.append(r)
            As.append(a)
            Bs.append(b)
    return np.concatenate(rs), np.concatenate(As), np.concatenate(Bs)


def fit_segment_noise(r: np.ndarray, a: np.ndarray, b: np.ndarray, trim: float = 4.0
                      ) -> Tuple[float, float, int]:
    """Fit ``r ~ N(0, sigma_px^2 a + sigma_angle^2 b)`` by maximum likelihood.

    Residuals beyond ``trim`` sigma are dropped and the fit repeated until the kept set no
    longer changes (at most 10 times).

    Returns:
        ``(sigma_px, sigma_angle_deg, residuals kept)``.

    Raises:
        ValueError: Fewer than two finite residuals (two noise terms cannot be fitted).
    """
    from scipy.optimize import minimize
    keep = np.isfinite(r) & np.isfinite(a) & np.isfinite(b)
    if np.count_nonzero(keep) < 2:
        raise ValueError(f'fit_segment_noise: {np.count_nonzero(keep)} finite residuals of '
                         f'{np.size(r)}; at least 2 are needed to fit the two noise terms')
    t = np.array([0.0, np.log(1e-3)])
    for _ in range(10):
        def nll(t: np.ndarray, k=keep) -> float:
            v = np.exp(2 * t[0]) * a[k] + np.exp(2 * t[1]) * b[k]
            return float(np.sum(np.log(v) + r[k] ** 2 / v))
        t = minimize(nll, t, method='Nelder-Mead', options={'xatol': 1e-8, 'fatol': 1e-10}).x
        v = np.exp(2 * t[0]) * a + np.exp(2 * t[1]) * b
        new = np.isfinite(r) & np.isfinite(a) & np.isfinite(b) & (np.abs(r) <= trim * np.sqrt(v))
        if np.array_equal(new, keep):
            break
        keep = new
    return float(np.exp(t[0])), float(np.degrees(np.exp(t[1]))), int(np.count_nonzero(keep))


def segment_noise(items: Sequence[YorkImage], scale: float = 1.0,
                  vp_params: VPParams = VPParams(), line_method: str = 'segmented_hough',
                  trim: float = 4.0) -> Tuple[float, float, int]:
    """Fit the segment noise ``(sigma_px, sigma_angle_deg)`` to residuals of true directions.

    Each image's labelled segments (:func:`segment_residuals`) are pooled and the two
    noise terms fitted by :func:`fit_segment_noise`.

    Returns:
        ``(sigma_px, sigma_angle_deg, segments kept)``.
    """
    res = [segment_residuals(item, scale, vp_params, line_method) for item in items]
    return fit_segment_noise(*(np.concatenate([x[i] for x in res]) for i in range(3)),
                             trim=trim)
