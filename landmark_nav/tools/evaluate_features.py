"""``landmark_nav evaluate-features <bag>``: score corner and line extractors per method.

The command's printing: the runners are
:mod:`landmark_nav.evaluation.feature_bags` (simulator bags against their ground-truth
corners and walls; any bag with ``/scan`` by the truth-free metrics).
"""

from typing import Optional, Sequence

from landmark_nav.evaluation.feature_bags import evaluate_bag_features
from landmark_nav.evaluation.scan_metrics import format_scan_metrics
from landmark_nav.laser.range_noise import RangeNoise


def format_tables(result: dict) -> str:
    """Render the figures as two Markdown tables."""
    est = result.get('sigma_r_estimate')
    lines = [f'scans: {result["scans"]}, extractor sigma_r = {100 * result["sigma_r"]:.1f} cm'
             + (f' ({RangeNoise(**est).describe()})' if est else ''),
             '', '| corner method | precision | recall | RMS error | ghosts/scan | ms/scan |',
             '| --- | --- | --- | --- | --- | --- |']
    for m, f in result['corners'].items():
        lines.append(f'| {m} | {f["precision"]:.3f} | {f["recall"]:.3f} | '
                     f'{100 * f["rms_error_m"]:.2f} cm | {f["ghosts_per_scan"]:.3f} | '
                     f'{f["median_ms_per_scan"]:.2f} |')
    lines += ['', '| line method | TruePos | FalsePos | sigma d rho (floor) | '
              'sigma d alpha (floor) | ms/scan |', '| --- | --- | --- | --- | --- | --- |']
    for m, f in result['lines'].items():
        lines.append(f'| {m} | {f["true_pos"]:.3f} | {f["false_pos"]:.3f} | '
                     f'{100 * f["sigma_drho_m"]:.2f} cm ({100 * f["floor_sigma_drho_m"]:.2f}) | '
                     f'{f["sigma_dalpha_deg"]:.3f} deg ({f["floor_sigma_dalpha_deg"]:.3f}) | '
                     f'{f["median_ms_per_scan"]:.2f} |')
    lines += ['', 'floor: what an efficient extractor would get on the same matched walls '
              '(Cramer-Rao bound from all beams on each wall, cut at the matching window)']
    return '\n'.join(lines)


def run(bag, every: int = 1, sigma_r=None, json_out=None,
        reference: Optional[str] = None, mount: Optional[Sequence[float]] = None,
        sensor_sigma_r: Optional[float] = None, scans: int = 20, seed: int = 0,
        truth_free: bool = False, progress: bool = False) -> str:
    """Evaluate the bag (``evaluate_bag_features``, JSON to ``json_out``); return the tables."""
    result, notes, free = evaluate_bag_features(
        bag, every=every, sigma_r=sigma_r, json_out=json_out, reference=reference,
        mount=mount, sensor_sigma_r=sensor_sigma_r, scans=scans, seed=seed,
        truth_free=truth_free, progress=progress)
    if not free:
        return format_tables(result)
    return '\n'.join(notes + [format_scan_metrics(result)])
