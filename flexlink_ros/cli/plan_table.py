"""
``flexlink plan``'s table: every candidate tried, with its errors and cost, and the choice.

Text for the terminal from :func:`studies.plan.run_plan`'s result (its rows as they are: a
candidate whose reduced model was not built shows dashes where its sizes and costs would be).
"""


def _fmt(value, spec, width):
    return f'{"-":>{width}}' if value is None else f'{value:>{width}{spec}}'


def _soft_choice(row):
    """Describe the chosen row's soft basis (the step's coordinates and model.soft_modes)."""
    tried = ', '.join(f'{t["step_size"]}: {max(t["error_coupler_mid"], t["error_lever_tip"]):.2e}'
                      for t in row.get('soft_tried', ()))
    if row['options'].get('soft_modes', 0) == 0:
        return f'all r coordinates stepped (soft_modes 0; tried {tried})'
    return (f'soft basis p = {row["step_size"]} (soft_modes {row["options"]["soft_modes"]}; '
            f'tried {tried})')


def plan_table(result):
    """Text table of :func:`studies.plan.run_plan`'s rows."""
    ref = result['reference']
    speeds = ', '.join(f'{s:g}' for s in result['speeds_rpm'])
    lines = [f'reference: {ref["label"]} ({ref["dofs"]} DOFs, {ref["source"]}, '
             f'{ref["seconds"]:.1f} s), speeds {speeds} rpm, tolerance {result["tolerance"]:g}',
             f'{"stage":<7} {"physics":<42} {"n":>3} {"modes":>5} {"stat":>4} {"grid":>4} '
             f'{"r":>3} {"p":>3} {"MB":>6} {"build s":>7} {"us":>6} {"phys c":>8} {"phys l":>8} '
             f'{"trunc c":>8} {"trunc l":>8} {"coupler":>8} {"lever":>8} ok']
    if result.get('fixed'):
        lines.insert(1, 'fixed in every candidate: ' + ', '.join(
            f'{name.replace("_", " ")} {"yes" if value else "no"}'
            for name, value in result['fixed'].items()))
    for row in result['alternatives']:
        o = row['options']
        built = row['size'] is not None
        lines.append(
            f'{row["stage"]:<7} {row["label"]:<42} {_fmt(row.get("dofs"), "d", 3)} '
            f'{_fmt(o["modes"] if built else None, "d", 5)} '
            f'{_fmt(o["static"] if built else None, "d", 4)} '
            f'{_fmt(o["grid_size"] if built else None, "d", 4)} {_fmt(row["size"], "d", 3)} '
            f'{_fmt(row.get("step_size"), "d", 3)} '
            f'{_fmt(None if row["bytes"] is None else row["bytes"] / 1e6, ".1f", 6)} '
            f'{_fmt(row["build_s"], ".1f", 7)} {_fmt(row["us_per_sample"], ".0f", 6)} '
            f'{_fmt(row.get("physics_error_coupler_mid"), ".2e", 8)} '
            f'{_fmt(row.get("physics_error_lever_tip"), ".2e", 8)} '
            f'{_fmt(row.get("truncation_error_coupler_mid"), ".2e", 8)} '
            f'{_fmt(row.get("truncation_error_lever_tip"), ".2e", 8)} '
            f'{_fmt(row["error_coupler_mid"], ".2e", 8)} '
            f'{_fmt(row["error_lever_tip"], ".2e", 8)} '
            f'{"yes" if row["meets_tolerance"] else "no"}')
    chosen = result['choice']
    if chosen:
        o = chosen['options']
        lines.append(f'choice: {chosen["label"]}, {o["modes"]} modes + {o["static"]} static, '
                     f'grid {o["grid_size"]} (r = {chosen["size"]}), '
                     f'{_soft_choice(chosen)}: coupler '
                     f'{chosen["error_coupler_mid"]:.2e}, lever {chosen["error_lever_tip"]:.2e}, '
                     f'{chosen["us_per_sample"]:.0f} us/sample')
    else:
        lines.append('choice: none of the candidates meets the tolerance'
                     + ('; leave out the fixed choices to let the plan try the others'
                        if result.get('fixed') else ''))
    lines.append(f'(physics error: full order vs the reference; trunc: reduced vs its own full '
                 f'order; coupler/lever: reduced vs the reference; plan took '
                 f'{result["seconds"]:.0f} s)')
    return '\n'.join(lines)
