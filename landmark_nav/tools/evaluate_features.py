"""``landmark_nav evaluate-features <bag>``: score corner and line extractors per method.

The command's printing: the runners are
:mod:`landmark_nav.evaluation.feature_bags` (simulator bags against their ground-truth
corners and walls; any bag with ``/scan`` by the truth-free metrics).
"""

from typing import Dict, Optional, Sequence, Tuple

from landmark_nav.evaluation.feature_bags import evaluate_bag_features
from landmark_nav.laser.range_noise import RangeNoise


def format_tables(result: dict) -> str:
    """Render the figures as two Markdown tables."""
    est = result.get('sigma_r_estimate')
    corner = result.get('corner_sigma_r', result['sigma_r'])
    lines = [f'scans: {result["scans"]}, extractor sigma_r = {100 * result["sigma_r"]:.1f} cm'
             + ('' if corner == result['sigma_r'] else f' (corners {100 * corner:.1f} cm)')
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


def _repeat_text(figures: dict, kind: str) -> str:
    """Render the ``kind`` ('line' or 'corner') repeatability of one method's figures."""
    fraction = figures[f'{kind}_repeatability']
    if fraction is None:
        return 'n/a (no reference poses)'
    return (f'{fraction:.3f} ({figures[f"{kind}_redetected"]}/'
            f'{figures[f"{kind}_opportunities"]})')


def _estimate_text(result: dict) -> str:
    """Return ' (estimated: ...)' when the extractors' sigma_r was estimated, else ''."""
    est = result.get('extractor_sigma_r_estimate')
    if not est:
        return ''
    return f' ({RangeNoise(**est).describe()})'


def _corner_text(result: dict) -> str:
    """Return ' (corners: X cm)' when the corner extractor's sigma_r differs, else ''."""
    corner = result.get('corner_sigma_r', result['extractor_sigma_r'])
    return '' if corner == result['extractor_sigma_r'] else f' (corners {100 * corner:.2f} cm)'


def format_scan_metrics(result: dict, title: str = '') -> str:
    """Render :func:`evaluate_scans` figures as two Markdown tables."""
    out = [f'{title}scans: {result["scans"]} ({result["ple_scans"]} drawn with seed '
           f'{result["seed"]} for f / ray RMSE / fit), {result["repeat_pairs"]} consecutive '
           f'pairs with reference poses; false-surface margin '
           f'{100 * result["false_surface_margin_m"]:.1f} cm (sigma_r '
           f'{100 * result["sigma_r"]:.1f} cm); extractors at sigma_r '
           f'{100 * result["extractor_sigma_r"]:.2f} cm' + _corner_text(result)
           + _estimate_text(result), '',
           '| line method | f | ray RMSE mean / median | without occluders (occluder beams '
           '/ hits) | f no-return | false-surface beams (scans) [sample] {> 30 cm (scans)} | '
           'fit RMS (beams) | lines >= 1 m re-detected | segments/scan | ms/scan median |',
           '| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |']
    for m, f in result['lines'].items():
        out.append(
            f'| {m} | {f["f"]:.3f} | {100 * f["ray_rmse_mean_m"]:.2f} / '
            f'{100 * f["ray_rmse_median_m"]:.2f} cm | '
            f'{100 * f["ray_rmse_no_occluders_mean_m"]:.2f} / '
            f'{100 * f["ray_rmse_no_occluders_median_m"]:.2f} cm ({f["occluder_beams_sample"]} / '
            f'{f["hit_beams_sample"]}) | {f["f_no_return"]:.3f} | '
            f'{f["false_surface_beams"]} ({f["false_surface_scans"]}) '
            f'[{f["false_surface_beams_sample"]}] {{{f["false_surface_beams_over_30cm"]} '
            f'({f["false_surface_scans_over_30cm"]})}} | '
            f'{100 * f["fit_rms_m"]:.2f} cm '
            f'({f["fit_beams"]}) | {_repeat_text(f, "line")} | '
            f'{f["segments_per_scan"]:.1f} | {f["median_ms_per_scan"]:.2f} |')
    out += ['', '| corner method | corners re-detected within 10 cm | counting the '
            'unobserved | structural (both arms >= 0.2 m, 6 beams) re-detected | others '
            're-detected '
            '| structural share | corners/scan | ms/scan median |',
            '| --- | --- | --- | --- | --- | --- | --- | --- |']
    for m, f in result['corners'].items():
        former = 'n/a'
        if f['corner_repeatability_with_unobserved'] is not None:
            former = (f'{f["corner_repeatability_with_unobserved"]:.3f} '
                      f'({f["corner_redetected"] + f["corner_unobserved_redetected"]}/'
                      f'{f["corner_opportunities"] + f["corner_unobserved"]})')
        classes = ' | '.join(_repeat_text({k.replace(f'_{c}', ''): v for k, v in f.items()
                                           if k.endswith(f'_{c}')}, 'corner')
                             for c in ('structural', 'other'))
        out.append(f'| {m} | {_repeat_text(f, "corner")} | {former} | {classes} | '
                   f'{f["structural_share"]:.2f} | {f["corners_per_scan"]:.2f} | '
                   f'{f["median_ms_per_scan"]:.2f} |')
    return '\n'.join(out)


def node_values(params_files: Sequence[str] = (), settings: Sequence[str] = ()
                ) -> Tuple[Dict[str, dict], Dict[str, dict]]:
    """Return the feature nodes' values of ``--params-file`` and of ``--set``, by node.

    A file gives each node its ``/**`` and own sections
    (:func:`landmark_nav.tools.node_parameters.read_params_file`). ``--set
    corner_extractor.NAME=VALUE`` or ``line_extractor.NAME=VALUE`` sets one node's
    parameter; ``--set NAME=VALUE`` sets it in each node that declares it.

    Raises:
        ValueError: An unreadable file, a malformed setting, or a bare NAME no node
            declares (naming the nearest declared one).
    """
    from landmark_nav.laser.extractor_configuration import EXTRACTORS, parameters
    from landmark_nav.parameter_names import unknown_parameter
    from landmark_nav.tools.node_parameters import given_parameters, parse_setting
    files = {node: given_parameters(params_files, [], node) for node in EXTRACTORS}
    sets: Dict[str, dict] = {node: {} for node in EXTRACTORS}
    for text in settings:
        key = text.partition('=')[0].strip()
        nodes = [node for node in EXTRACTORS if key.startswith(node + '.')]
        name, value = parse_setting(text, nodes[0] if nodes else '')
        if not nodes:
            nodes = [node for node in EXTRACTORS if name in parameters(node)]
        if not nodes:
            known = {k for node in EXTRACTORS for k in parameters(node)}
            raise ValueError(f'--set {text!r}: '
                             + unknown_parameter(' or '.join(EXTRACTORS), name, known))
        for node in nodes:
            sets[node][name] = value
    return files, sets


def run(bag, every: int = 1, sigma_r=None, json_out=None,
        reference: Optional[str] = None, mount: Optional[Sequence[float]] = None,
        sensor_sigma_r: Optional[float] = None, scans: int = 20, seed: int = 0,
        truth_free: bool = False, progress: bool = False, params_files: Sequence[str] = (),
        settings: Sequence[str] = ()) -> str:
    """Evaluate the bag (``evaluate_bag_features``, JSON to ``json_out``); return the tables.

    ``params_files`` and ``settings``: the ``--params-file`` and ``--set`` of the command
    (:func:`node_values`).
    """
    files, sets = node_values(params_files, settings)
    result, notes, free = evaluate_bag_features(
        bag, every=every, sigma_r=sigma_r, json_out=json_out, reference=reference,
        mount=mount, sensor_sigma_r=sensor_sigma_r, scans=scans, seed=seed,
        truth_free=truth_free, progress=progress, files=files, settings=sets)
    if not free:
        return format_tables(result)
    return '\n'.join(notes + [format_scan_metrics(result)])
