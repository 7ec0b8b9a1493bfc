"""The plan's table (cli/plan_table.py): a row per candidate, dashes where nothing was built."""

from flexlink_ros.cli.plan_table import plan_table


def _row(stage, label, size, meets, **extra):
    built = size is not None
    options = {'modes': 4 if built else 8, 'static': 2, 'grid_size': 64, 'soft_modes': -1}
    return {'stage': stage, 'label': label, 'dofs': 30, 'options': options, 'size': size,
            'step_size': 3 if built else None, 'bytes': 2.5e6 if built else None,
            'build_s': 1.5 if built else None, 'us_per_sample': 7.0 if built else None,
            'physics_error_coupler_mid': 0.004, 'physics_error_lever_tip': 0.006,
            'error_coupler_mid': 0.008 if built else None,
            'error_lever_tip': 0.009 if built else None, 'meets_tolerance': meets,
            'soft_tried': [{'step_size': 3, 'error_coupler_mid': 0.008,
                            'error_lever_tip': 0.009}], **extra}


def result(choice=True):
    rows = [_row('physics', '2 el, rigid crank', None, False),
            _row('size', '4 el, flex crank', 6, True, truncation_error_coupler_mid=0.001,
                 truncation_error_lever_tip=0.002)]
    return {'reference': {'label': '4 el, flex crank', 'dofs': 36, 'source': 'full order',
                          'seconds': 12.0},
            'speeds_rpm': [269.0, 391.0], 'tolerance': 0.02, 'fixed': {'rigid_crank': True},
            'alternatives': rows, 'choice': rows[1] if choice else None, 'seconds': 30.0}


def test_a_row_per_candidate_with_dashes_where_no_model_was_built_and_the_choice():
    lines = plan_table(result()).splitlines()
    assert lines[0].startswith('reference: 4 el, flex crank (36 DOFs, full order, 12.0 s), '
                               'speeds 269, 391 rpm, tolerance 0.02')
    assert lines[1] == 'fixed in every candidate: rigid crank yes'
    physics, size = lines[3], lines[4]
    assert physics.split()[-1] == 'no' and physics.split().count('-') == 12
    assert size.split()[-1] == 'yes' and '-' not in size.split()
    assert lines[5] == ('choice: 4 el, flex crank, 4 modes + 2 static, grid 64 (r = 6), soft '
                        'basis p = 3 (soft_modes -1; tried 3: 9.00e-03): coupler 8.00e-03, '
                        'lever 9.00e-03, 7 us/sample')


def test_without_a_choice_it_says_to_leave_out_the_fixed_choices():
    text = plan_table(result(choice=False))
    assert ('choice: none of the candidates meets the tolerance; leave out the fixed choices'
            in text)
