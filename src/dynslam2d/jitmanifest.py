"""The kernels a first run of ``dynslam2d run`` (sim:paper, default configuration) compiles, in order of
first use, with the argument types of each (numba type names) and its compile time: what :mod:`dynslam2d.jitwarm`
compiles in a second process while a cold run compiles in its own order.

Written by ``benchmarks/record_kernels.py`` (do not edit by hand); tests/test_jitwarm.py checks it against the
signatures the kernels hold after a real run. A kernel missing here is compiled by the run itself, as before.
"""

#: (module.qualname, argument types) in order of first use; one signature per kernel.
KERNELS: tuple[tuple[str, str], ...] = (
    ('dynslam2d.sim.world._cast_kernel',
     "(float64, float64, Array(float64, 1, 'C'), Array(float64, 1, 'C'), Array(float64, 2, 'C'), "
     "Array(int32, 1, 'C'), Array(float64, 2, 'C'), Array(int32, 1, 'C'), float64,)"),
    ('dynslam2d.detect.body._drop_body',
     "(Array(float64, 1, 'C'), float64, float64, Array(bool, 1, 'C'), bool, Array(float64, 1, 'C'), "
     "float64, bool, Array(bool, 1, 'C'), bool, Array(float64, 1, 'C'), Array(bool, 1, 'C'),)"),
    ('dynslam2d.slam.matcher.gated_points',
     "(Array(float64, 1, 'C'), Array(float64, 1, 'C', True), Array(float64, 1, 'C', True), Array(bool, 1, "
     "'C'), float64, float64, float64, float64, float64, bool, Array(bool, 1, 'C'),)"),
    ('dynslam2d.detect.body._observe_beams',
     "(Array(float64, 1, 'C'), Array(bool, 1, 'C'), Array(float64, 2, 'C'), Array(int64, 2, 'C'), "
     "Array(bool, 1, 'C'), Array(bool, 1, 'C'), Array(float64, 1, 'C'), Array(bool, 1, 'C'), "
     "Array(float64, 1, 'C'), float64, float64, float64,)"),
    ('dynslam2d.detect.segment.detect_scan',
     "(Array(float64, 1, 'C'), Array(float64, 1, 'C'), Array(bool, 1, 'C'), Array(float64, 2, 'C'), bool, "
     "Array(float64, 1, 'C'), bool, Array(float64, 1, 'C'), Array(float64, 1, 'C'), float64, float64, "
     "float64, float64, bool, float64, Array(float64, 1, 'C'), float64, Array(float64, 1, 'C'), "
     "Array(float64, 2, 'C'), Array(float64, 1, 'C'), Array(float64, 1, 'C'), bool, Array(float32, 2, "
     "'C'), int64, int64, float64, float64,)"),
    ('dynslam2d.detect.kernels_update.birth_rows',
     "(Array(float64, 2, 'C'), Array(float64, 3, 'C'), Array(float64, 2, 'C'), Array(int8, 2, 'C'), "
     "Array(int64, 2, 'C'), Array(float64, 1, 'C'), Array(float64, 3, 'C'), Array(int64, 2, 'C'), "
     "Array(int64, 1, 'C'), Array(int64, 1, 'C'), Array(int8, 1, 'C'), Array(float64, 1, 'C'), "
     "Array(float64, 2, 'C'), Array(bool, 3, 'C'), Array(float64, 2, 'C'), Array(float64, 2, 'C'), "
     "Array(float64, 3, 'C'), Array(int8, 2, 'C'), Array(float64, 2, 'C'), Array(float64, 1, 'C'), "
     'float64, bool, float64,)'),
    ('dynslam2d.detect.kernels_update.report_rows',
     "(Array(float64, 2, 'C'), Array(int8, 2, 'C'), Array(float64, 2, 'C'), Array(float64, 3, 'C'), "
     "Array(int64, 2, 'C'), Array(int64, 1, 'C'), float64,)"),
    ('dynslam2d.slam.ledgerkernels.record_cells',
     "(Array(int64, 1, 'C'), Array(int64, 1, 'C'), Array(float64, 1, 'C'), Array(float64, 1, 'C', True), "
     "Array(float64, 1, 'C', True), Array(bool, 1, 'C'), Array(bool, 1, 'A'), float64, float64, float64, "
     "float64, float64, float64, Array(float64, 1, 'C'), UniTuple(Array(float32, 2, 'C', False, "
     "aligned=True), 3), UniTuple(Array(int32, 2, 'C', False, aligned=True), 3), UniTuple(int64, 3), "
     'UniTuple(int64, 3), bool,)'),
    ('dynslam2d.slam.ledgerkernels.level_rows',
     "(UniTuple(Array(float32, 2, 'C', False, aligned=True), 3), UniTuple(Array(int32, 2, 'C', False, "
     "aligned=True), 3), UniTuple(int64, 3), UniTuple(int64, 3), int64, Array(int64, 2, 'C'), "
     "Array(int64, 1, 'C'),)"),
    ('dynslam2d.slam.ledgerkernels.stand_marks',
     "(Array(float64, 2, 'C'), Array(int64, 1, 'C'), Array(float64, 2, 'C'), Array(float64, 2, 'C'), "
     "Array(int64, 1, 'C'), Array(int64, 1, 'C'), Array(float64, 2, 'C'), Array(int64, 1, 'C'), int64, "
     'float64, float64, float64,)'),
    ('dynslam2d.slam.raycast.integrate_levels',
     "(Array(float64, 2, 'C'), Array(float64, 2, 'C'), float64, float64, float64, float64, "
     "UniTuple(Array(float32, 2, 'C', False, aligned=True), 4), UniTuple(Array(uint32, 2, 'C', False, "
     "aligned=True), 4), UniTuple(Array(int32, 2, 'C', False, aligned=True), 4), int64, UniTuple(float64, "
     "4), UniTuple(int64, 4), UniTuple(int64, 4), UniTuple(int64, 4), Array(float64, 1, 'C'), bool, "
     "int64, float64, float64, float64, Array(uint64, 2, 'C'), float64,)"),
    ('dynslam2d.slam.raycast.ray_ends',
     "(Array(float64, 2, 'C'), Array(float64, 2, 'C'), float64, float64, float64, float64,)"),
    ('dynslam2d.slam.matcher.match_pyramid',
     "(Array(uint32, 2, 'C'), Array(uint32, 2, 'C'), Array(uint32, 2, 'C'), Array(float64, 2, 'C'), "
     "Array(float64, 2, 'C'), float64, float64, float64, int64, int64, bool, bool, float64, float64, "
     "float64, float64, bool, float64, float64, float64, Array(float64, 3, 'C'), bool, float64, "
     "Array(float64, 2, 'C'), Array(float64, 1, 'C'), float64, float64, float64, float64,)"),
    ('dynslam2d.slam.correlative._search_points',
     "(Array(float64, 2, 'C'), Array(int64, 1, 'C', True), float64,)"),
    ('dynslam2d.slam.correlative._search_cells',
     "(Array(float64, 2, 'C'), Array(float64, 1, 'C'), Array(float64, 1, 'C'), float64, float64, int64,)"),
    ('dynslam2d.slam.correlative._search_table',
     "(Array(uint32, 2, 'C'), int64, int64, int64, int64, int64, int64, int64, int64, int64, "
     "Array(float32, 1, 'C'),)"),
    ('dynslam2d.slam.correlative.branch_and_bound',
     "(Array(float32, 2, 'C'), int64, Array(int64, 2, 'C'), Array(int64, 2, 'C'), bool, int64, "
     "Array(float64, 1, 'C'), float64, float64, Array(int64, 1, 'C'), float64, float64,)"),
    ('dynslam2d.vacated.vacated_scan_kernel',
     "(Array(float64, 1, 'C'), Array(float64, 1, 'C', True), Array(float64, 1, 'C', True), Array(bool, 1, "
     "'C'), float64, float64, float64, Array(float32, 2, 'C'), int64, int64, Array(float64, 1, 'C'), "
     "Array(int64, 1, 'C'), Array(uint8, 2, 'C'), Array(float64, 1, 'C'), Array(uint64, 2, 'C'), float64, "
     'float64, float64,)'),
    ('dynslam2d.detect.kernels.cv_predict',
     "(Array(float64, 2, 'C'), Array(float64, 3, 'C'), Array(int64, 1, 'C'), Array(float64, 2, 'C'), "
     "Array(float64, 2, 'C'),)"),
    ('dynslam2d.detect.kernels_assign.associate_update',
     "(Array(float64, 1, 'C'), Array(int64, 1, 'C'), Array(int8, 2, 'C'), Array(int64, 1, 'C'), "
     "Array(float64, 2, 'C'), Array(float64, 3, 'C'), Array(int8, 1, 'C'), Array(float64, 1, 'C'), "
     "Array(float64, 2, 'C'), Array(bool, 3, 'C'), Array(float64, 2, 'C'), Array(float64, 2, 'C'), "
     "Array(float64, 1, 'C'), Array(float64, 1, 'C'), Array(int64, 1, 'C'), Array(int64, 1, 'C'), "
     "Array(float64, 1, 'C'), Array(bool, 1, 'C'), Array(int64, 1, 'C'), Array(float64, 1, 'C'), "
     "Array(float64, 3, 'C'), bool, float64, float64, Array(float64, 2, 'C'), Array(int64, 1, 'C'), "
     "Array(int64, 1, 'C'), Array(int64, 1, 'C'), Array(int64, 1, 'C'), bool, float64, float64, float64, "
     "float64, float64, Array(float64, 3, 'C'), bool,)"),
    ('dynslam2d.detect.kernels_update.fragment_hosts_rows',
     "(Array(float64, 1, 'C'), Array(float64, 1, 'C'), Array(int64, 1, 'C'), Array(int64, 1, 'C'), "
     "Array(int64, 1, 'C'), Array(float64, 2, 'C'), Array(float64, 2, 'C'), Array(int64, 1, 'C'), "
     'float64,)'),
    ('dynslam2d.detect.kernels.seen_through_refs',
     "(Array(float64, 2, 'C'), Array(float64, 1, 'C'), Array(float64, 1, 'C'), Array(float64, 1, 'C'), "
     "Array(float64, 1, 'C'), int64, float64, Array(bool, 1, 'C'),)"),
    ('dynslam2d.filter._movers_kernel',
     "(Array(float64, 1, 'C'), Array(float64, 1, 'C', True), Array(float64, 1, 'C', True), Array(bool, 1, "
     "'C'), float64, float64, float64, float64, Array(float64, 2, 'C'), Array(float64, 2, 'C'), "
     "Array(int64, 1, 'C'), Array(int64, 1, 'C'), Array(int64, 1, 'C'), float64, bool, bool, bool, "
     'float64, float64,)'),
    ('dynslam2d.slam.cleanup._add_scan',
     "(Array(float64, 1, 'C'), Array(float64, 1, 'C', True), Array(float64, 1, 'C', True), Array(bool, 1, "
     "'C'), Array(bool, 1, 'C'), float64, float64, float64, float64, float64, float64, float64, float64, "
     "float64, Array(int32, 2, 'C'), Array(uint16, 3, 'C'), int64, int64, int64, int64, int64, int64, "
     "int64, int64, float64, Array(uint8, 1, 'C'),)"),
    ('dynslam2d.viz.collect._removed_points',
     "(Array(bool, 1, 'C'), Array(bool, 1, 'C'), Array(float64, 1, 'C'), Array(float64, 1, 'C', True), "
     "Array(float64, 1, 'C', True), int64, int64, float64, float64, float64, float64,)"),
)

#: CPU time of each kernel's compile (s, the kernels it compiles in turn included) in a one-core cold run when
#: recorded: the background compile's estimate of how far ahead of the run a kernel is (its order, docs/speed.md).
COMPILE_S: dict[str, float] = {
    'dynslam2d.sim.world._cast_kernel': 0.44,
    'dynslam2d.detect.body._drop_body': 0.21,
    'dynslam2d.slam.matcher.gated_points': 0.40,
    'dynslam2d.detect.body._observe_beams': 0.17,
    'dynslam2d.detect.segment.detect_scan': 7.70,
    'dynslam2d.detect.kernels_update.birth_rows': 0.33,
    'dynslam2d.detect.kernels_update.report_rows': 0.38,
    'dynslam2d.slam.ledgerkernels.record_cells': 1.82,
    'dynslam2d.slam.ledgerkernels.level_rows': 0.40,
    'dynslam2d.slam.ledgerkernels.stand_marks': 0.30,
    'dynslam2d.slam.raycast.integrate_levels': 1.57,
    'dynslam2d.slam.raycast.ray_ends': 0.06,
    'dynslam2d.slam.matcher.match_pyramid': 3.16,
    'dynslam2d.slam.correlative._search_points': 0.19,
    'dynslam2d.slam.correlative._search_cells': 0.38,
    'dynslam2d.slam.correlative._search_table': 0.92,
    'dynslam2d.slam.correlative.branch_and_bound': 1.72,
    'dynslam2d.vacated.vacated_scan_kernel': 3.72,
    'dynslam2d.detect.kernels.cv_predict': 0.31,
    'dynslam2d.detect.kernels_assign.associate_update': 8.44,
    'dynslam2d.detect.kernels_update.fragment_hosts_rows': 0.29,
    'dynslam2d.detect.kernels.seen_through_refs': 0.30,
    'dynslam2d.filter._movers_kernel': 1.58,
    'dynslam2d.slam.cleanup._add_scan': 1.56,
    'dynslam2d.viz.collect._removed_points': 0.19,
}
