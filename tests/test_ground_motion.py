import numpy as np
import pytest

from calib_masonry.errors import InputError
from calib_masonry.simulation.ground_motion import G, constant_acceleration, read_accelerogram, synthetic_motion


def test_synthetic_scaled_to_pga_and_seeded():
    a = synthetic_motion(0.3, 10.0, seed=4)
    b = synthetic_motion(0.3, 10.0, seed=4)
    c = synthetic_motion(0.3, 10.0, seed=5)
    assert np.isclose(a.pga, 0.3 * G, rtol=1e-9)
    assert np.array_equal(a.displacement, b.displacement)
    assert not np.allclose(a.displacement, c.displacement)
    assert np.isclose(a.duration, 10.0)


def test_acceleration_is_second_difference_of_displacement():
    m = synthetic_motion(0.2, 5.0, seed=1, components=2)
    d = m.displacement
    acc = (d[2:] - 2 * d[1:-1] + d[:-2]) / m.dt**2
    np.testing.assert_allclose(m.acceleration[1:-1], acc)
    assert np.abs(m.acceleration[:, 1]).max() > 0  # two components


def test_baseline_corrected_plate_returns_near_rest():
    m = synthetic_motion(0.5, 20.0, seed=2)
    peak = np.abs(m.displacement).max()
    assert np.abs(m.displacement[-1]).max() < 0.2 * peak
    v = np.diff(m.displacement, axis=0) / m.dt
    assert np.abs(v[-50:]).max() < 0.1 * np.abs(v).max()


def test_constant_acceleration_is_exact():
    m = constant_acceleration(2.0, 1.0, dt=0.01)
    np.testing.assert_allclose(m.acceleration[1:-1, 0], 2.0)
    assert np.isclose(m.displacement[-1, 0], 1.0)


def test_mean_acceleration_per_frame_keeps_velocities_exact():
    m = constant_acceleration(2.0, 1.0, dt=0.001)
    t = np.arange(-3, 30) / 25.0  # frames at 25 fps, three of them before the ground moves
    acc = m.mean_acceleration(t)
    np.testing.assert_allclose(acc[:3], 0.0)
    np.testing.assert_allclose(acc[3:28, 0], 2.0, rtol=1e-9)  # frames 3 .. 28 span the 1 s record
    np.testing.assert_allclose(acc[28:], 0.0)  # keeps its last velocity after the record ends
    q = synthetic_motion(0.4, 6.0, seed=3, components=2)
    t = np.arange(0, 151) / 25.0
    v = np.cumsum(q.mean_acceleration(t) * np.diff(t)[:, None], axis=0)  # velocity at each frame
    d = np.concatenate([[[0.0, 0.0]], np.cumsum(0.5 * (np.vstack([[0, 0], v[:-1]]) + v) / 25.0, axis=0)])
    ref = q.displacement_at(t)
    assert np.abs(d - ref).max() < 0.05 * np.abs(ref).max()


def test_accelerogram_csv(tmp_path):
    t = np.arange(0, 5, 0.01)
    a = 0.1 * np.sin(2 * np.pi * 2.0 * t) * np.minimum(t, 1.0)
    p = tmp_path / "rec.csv"
    p.write_text("time,acc_g\n" + "\n".join(f"{x:.3f},{y:.6f}" for x, y in zip(t, a)))
    m = read_accelerogram(p)
    assert np.isclose(m.dt, 0.01)
    assert 0.05 * G < m.pga < 0.15 * G


@pytest.mark.parametrize(
    "text, msg",
    [
        ("", "at least 3 rows"),
        ("t,a\n0,1\n0,2\n0,3\n", "line 3: time 0 s does not increase"),
        ("0,1\n1,x\n2,3\n", "line 2: '1,x' is not numbers"),
        ("t,a\n0,0.1\n0.01,nan\n0.02,0.1\n", "line 3: '0.01,nan' holds NaN or inf"),
        ("0,0.1\n0.01,inf\n0.02,0.1\n", "line 2"),
        ("0,0.1\n0.01,0.2\n0.02,0.1\n0.05,0.0\n0.06,0.1\n", "line 4: time step 0.03 s"),
        ("0,0.1,0.2,0.3\n0.01,0,0,0\n0.02,0,0,0\n", "line 1: 4 columns"),
        ("0,0\n1,0.1\n2,0\n3,0\n", "time step 1 s is coarser than any strong-motion record"),
    ],
)
def test_accelerogram_errors(tmp_path, text, msg):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(InputError, match=msg):
        read_accelerogram(p)
    with pytest.raises(InputError, match="not found"):
        read_accelerogram(tmp_path / "none.csv")


def test_two_column_record_shakes_along_x_and_three_columns_along_both(tmp_path):
    t = np.arange(0, 4, 0.005)
    a = 0.2 * np.sin(np.pi * t / t[-1]) ** 2 * np.sin(2 * np.pi * 1.5 * t)  # starts and ends at rest
    two = tmp_path / "two.csv"
    two.write_text("\n".join(f"{x:.3f},{y:.6f}" for x, y in zip(t, a)))
    three = tmp_path / "three.csv"
    three.write_text("time;ax;ay\n" + "\n".join(f"{x:.3f};{y:.6f};{-y:.6f}" for x, y in zip(t, a)))
    m2, m3 = read_accelerogram(two), read_accelerogram(three)
    assert m2.displacement.shape == (len(t), 2) and np.all(m2.displacement[:, 1] == 0)
    assert m2.mean_acceleration(np.arange(0, 4, 0.04)).shape == (99, 2)
    assert np.allclose(m3.displacement[:, 1], -m3.displacement[:, 0])
    in_ms2 = read_accelerogram(two, units="m/s2")
    assert in_ms2.pga == pytest.approx(m2.pga / G, rel=1e-9)


def test_a_record_with_decimal_commas_or_in_gal_reads_as_the_same_motion(tmp_path):
    """A spreadsheet in a European locale writes ``0,005;0,012`` (semicolons between the columns,
    commas for the decimals): read as the record it is, where it was refused as four columns. A
    record in cm/s2 (gal, as ESM, ITACA and K-NET give them) with ``--units cm/s2``, which the
    reader knew but the command line and the simulation settings refused."""
    from calib_masonry.simulation.run import SimulationConfig

    t = np.arange(0, 4, 0.005)
    a = 0.2 * np.sin(np.pi * t / t[-1]) ** 2 * np.sin(2 * np.pi * 1.5 * t)
    dots = tmp_path / "dots.csv"
    dots.write_text("\n".join(f"{x:.3f},{y:.6f},{-y:.6f}" for x, y in zip(t, a)))
    commas = tmp_path / "commas.csv"
    commas.write_text("Zeit;ax;ay\n" + "\n".join(f"{x:.3f};{y:.6f};{-y:.6f}".replace(".", ",") for x, y in zip(t, a)))
    m, c = read_accelerogram(dots), read_accelerogram(commas)
    assert c.dt == m.dt and np.array_equal(c.displacement, m.displacement)
    gal = tmp_path / "gal.csv"
    gal.write_text("\n".join(f"{x:.3f},{100 * G * y:.6f}" for x, y in zip(t, a)))
    assert read_accelerogram(gal, units="cm/s2").pga == pytest.approx(read_accelerogram(dots).pga, rel=1e-5)
    assert SimulationConfig(accelerogram=gal, record_units="cm/s2").record_units == "cm/s2"
    with pytest.raises(InputError, match=r"gal.csv.*peak is .* g read in g.*--units m/s2 or --units cm/s2"):
        read_accelerogram(gal)


def test_a_record_timed_in_milliseconds_is_refused_naming_them(tmp_path):
    # a time column in ms (0, 5, 10, ...) read as seconds is a 5 s step: the refusal said to
    # resample the record finer; it now names the milliseconds
    t = np.arange(0, 2000, 5.0)
    p = tmp_path / "ms.csv"
    p.write_text("time_ms,a\n" + "".join(f"{x:.1f},{0.1 * np.sin(x / 100):.5f}\n" for x in t))
    with pytest.raises(InputError, match=r"ms.csv.*time step 5 s.*in milliseconds \(5 ms\), give it in seconds"):
        read_accelerogram(p)


def test_a_record_of_accelerations_alone_reads_with_its_time_step(tmp_path):
    """Many records come as accelerations alone, one a line or several a line in reading order
    (an agency's fixed-width file, a column exported from a processing tool), the time step
    given apart. It was refused as "1 columns"; now ``dt`` (``--dt``, a study's ``dt_s``) reads it
    as the same motion as the file with a time column, and without it the refusal names ``--dt``."""
    from calib_masonry.simulation.run import SimulationConfig, motion_for

    t = np.arange(0, 4, 0.01)
    a = 0.2 * np.sin(np.pi * t / t[-1]) ** 2 * np.sin(2 * np.pi * 1.5 * t)
    timed = tmp_path / "timed.csv"
    timed.write_text("\n".join(f"{x:.3f},{y:.6f}" for x, y in zip(t, a)))
    column = tmp_path / "column.txt"
    column.write_text("acceleration (g), station X\n" + "\n".join(f"{y:.6f}" for y in a))
    rows = tmp_path / "rows.txt"
    rows.write_text("\n".join("  ".join(f"{y:.6f}" for y in a[k : k + 8]) for k in range(0, len(a), 8)))
    want = read_accelerogram(timed)
    for f in (column, rows):
        m = read_accelerogram(f, dt=0.01)
        assert m.dt == want.dt == 0.01  # the time column's step to its own digits, not their rounding
        np.testing.assert_array_equal(m.displacement, want.displacement)
    y = read_accelerogram(column, dt=0.01, path_y=rows)  # two components, each alone with the same step
    np.testing.assert_allclose(y.displacement[:, 1], want.displacement[:, 0], rtol=1e-9, atol=1e-15)
    assert motion_for(SimulationConfig(accelerogram=column, record_dt_s=0.01)).pga == pytest.approx(want.pga)
    with pytest.raises(InputError, match=r"column.txt: line 2: one column, .*--dt SECONDS"):
        read_accelerogram(column)
    with pytest.raises(InputError, match=r"timed.csv: its first column steps evenly from 0 by 0.01: a time column"):
        read_accelerogram(timed, dt=0.01)
    for bad in (0.0, -0.01, 5.0, float("nan")):
        with pytest.raises(InputError, match=r"--dt .*must lie in 0..0.05 s"):
            SimulationConfig(accelerogram=column, record_dt_s=bad)
    at2 = tmp_path / "RSN1.AT2"
    at2.write_text("PEER\nx\nACCELERATION TIME SERIES IN UNITS OF G\nNPTS=   400, DT=   .0100 SEC\n" + rows.read_text())
    assert read_accelerogram(at2, dt=0.01).dt == 0.01  # the header's own step, given again
    with pytest.raises(InputError, match=r"RSN1.AT2: its header gives its time step, 0.01 s, not 0.02"):
        read_accelerogram(at2, dt=0.02)


def test_peer_at2_record(tmp_path):
    rng = np.random.default_rng(0)
    values = 0.1 * rng.standard_normal(203)
    body = "\n".join("  ".join(f"{v:.7E}" for v in values[k : k + 5]) for k in range(0, len(values), 5))
    for header in ("NPTS=   203, DT=   .0100 SEC", "  203    .0100    NPTS, DT"):
        p = tmp_path / "RSN0_TEST.AT2"
        p.write_text(
            "PEER NGA STRONG MOTION DATABASE RECORD\nTest event, station, comp 000\n"
            f"ACCELERATION TIME SERIES IN UNITS OF G\n{header}\n{body}\n"
        )
        with pytest.warns(UserWarning, match="does not start and end at rest"):  # white noise does not
            m = read_accelerogram(p)
        assert m.dt == pytest.approx(0.01) and len(m.displacement) == 203
        assert m.source == "RSN0_TEST.AT2"
    p.write_text(p.read_text().replace("  203    .0100", "  204    .0100"))
    with pytest.raises(InputError, match="NPTS = 204 but the file holds 203"):
        read_accelerogram(p)


def test_pga_scales_a_record_and_without_it_the_record_runs_as_recorded(tmp_path):
    from calib_masonry.simulation.run import SimulationConfig, motion_for

    t = np.arange(0, 4, 0.005)
    p = tmp_path / "rec.csv"
    env = np.sin(np.pi * t / t[-1]) ** 2  # a record that starts and ends at rest
    p.write_text("\n".join(f"{x:.3f},{0.2 * e * np.sin(2 * np.pi * 1.5 * x):.6f}" for x, e in zip(t, env)))
    recorded = motion_for(SimulationConfig(accelerogram=p))
    assert recorded.pga == pytest.approx(read_accelerogram(p).pga)
    scaled = motion_for(SimulationConfig(accelerogram=p, pga_g=0.5))
    assert scaled.pga == pytest.approx(0.5 * G, rel=1e-9)
    with pytest.raises(InputError, match="must lie in 0..5 g"):
        SimulationConfig(pga_g=1e9)


def test_negative_pga_refused():
    with pytest.raises(InputError, match="pga"):
        synthetic_motion(-0.1, 5.0, seed=0)


def test_run_motion_peaks_at_the_pga_and_is_the_same_record_at_every_frame_rate():
    # the joint model and the verdict read the record's samples (not Bullet's frame means): the
    # samples peak at the PGA, and a run at 50 fps shakes with the very record of a run at 25 fps
    from calib_masonry.simulation.run import SimulationConfig, motion_for
    from calib_masonry.simulation.scene import SolverSettings

    for components in (1, 2):
        raw = synthetic_motion(0.6, 10.0, seed=2, components=components)
        assert raw.applied_peak(25) < 0.95 * raw.pga  # broadband: frame means peak lower than the samples
        runs = [
            motion_for(
                SimulationConfig(
                    pga_g=0.6, duration_s=10.0, seed=2, components=components, solver=SolverSettings(fps=fps)
                )
            )
            for fps in (25, 50)
        ]
        for m in runs:
            assert np.isclose(m.pga, 0.6 * G, rtol=1e-9)
            assert m.applied_peak(25) < m.pga
            # the same record, only scaled
            i = np.argmax(np.abs(raw.displacement[:, 0]))
            np.testing.assert_allclose(
                m.displacement, raw.displacement * (m.displacement[i, 0] / raw.displacement[i, 0]), atol=1e-12
            )
        np.testing.assert_array_equal(runs[0].acceleration, runs[1].acceleration)


def test_a_record_starts_from_rest():
    # displacement and velocity zero at t = 0 and the first frame's applied acceleration a small
    # fraction of the peak (the record is tapered in over TAPER_S): the structure is not jolted
    from calib_masonry.simulation.ground_motion import TAPER_S
    from calib_masonry.simulation.run import SimulationConfig, motion_for

    for seed in (0, 1, 2):
        m = motion_for(SimulationConfig(pga_g=0.3, seed=seed))
        assert np.all(m.displacement[0] == 0.0)
        v = np.diff(m.displacement, axis=0) / m.dt
        assert np.abs(v[0]).max() < 1e-3 * np.abs(v).max()
        t, a = m.frame_means(25)
        assert np.abs(a[0]).max() < 0.02 * np.abs(a).max()
        # after the taper the record is the record: its peak is where the strong phase is
        assert t[np.abs(a).max(axis=1).argmax()] > TAPER_S


def test_a_record_not_at_rest_at_its_ends_is_warned_about_and_its_own_peak_kept(tmp_path):
    """A 0.05 g sine at 0.4 Hz stopped at full amplitude: starting it from rest raised its peak by
    more than 5 % without a word, and the summary called the processed peak the record's. Now a
    warning says why, and the record's own peak is kept (record_peak_g)."""
    t = np.arange(0.0, 8.0 + 0.625 + 1e-9, 0.01)  # ends at a crest of the 0.4 Hz sine
    p = tmp_path / "sine.csv"
    p.write_text("".join(f"{a:.4f},{0.05 * np.sin(2 * np.pi * 0.4 * a):.6f}\n" for a in t))
    with pytest.warns(UserWarning, match=r"sine.csv: starting the record from rest .* changes its peak"):
        m = read_accelerogram(p)
    assert m.recorded_peak == pytest.approx(0.05 * G, rel=1e-3)
    assert abs(m.pga / m.recorded_peak - 1) > 0.05
    assert m.scaled(2.0).recorded_peak == pytest.approx(0.1 * G, rel=1e-3)
    # a record that starts and ends at rest passes without a warning
    q = tmp_path / "rest.csv"
    env = np.sin(np.pi * t / t[-1]) ** 2
    q.write_text(
        "".join(f"{a:.4f},{0.05 * e * np.sin(2 * np.pi * 2.0 * a):.6f}\n" for a, e in zip(t, env, strict=True))
    )
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_accelerogram(q)


def _esm_file(path, values, *, dt=0.005, stream="HNE", units="cm/s^2", data_type="ACCELERATION", ndata=None):
    """An ESM / ITACA ASCII record as the database writes it (DYNA 1.2: 64 header lines of KEY: value,
    then one value a line)."""
    head = {
        "EVENT_NAME": "CENTRAL_ITALY",
        "EVENT_ID": "EMSC-20161030_0000029",
        "EVENT_DATE_YYYYMMDD": "20161030",
        "EVENT_TIME_HHMMSS": "064017",
        "EVENT_LATITUDE_DEGREE": "42.8320",
        "EVENT_LONGITUDE_DEGREE": "13.1110",
        "EVENT_DEPTH_KM": "9.2",
        "MAGNITUDE_W": "6.5",
        "MAGNITUDE_L": "",
        "FOCAL_MECHANISM": "Normal faulting",
        "NETWORK": "IT",
        "STATION_CODE": "NRC",
        "STATION_NAME": "NORCIA",
        "STATION_LATITUDE_DEGREE": "42.792500",
        "STATION_LONGITUDE_DEGREE": "13.096400",
        "STATION_ELEVATION_M": "",
        "VS30_M/S": "",
        "SITE_CLASSIFICATION_EC8": "B*",
        "EPICENTRAL_DISTANCE_KM": "4.6",
        "DATE_TIME_FIRST_SAMPLE_YYYYMMDD_HHMMSS": "20161030_064008.000",
        "DATE_TIME_FIRST_SAMPLE_PRECISION": "milliseconds",
        "SAMPLING_INTERVAL_S": f"{dt:.6f}",
        "NDATA": str(len(values) if ndata is None else ndata),
        "DURATION_S": f"{len(values) * dt:.3f}",
        "STREAM": stream,
        "UNITS": units,
        "INSTRUMENT": "HN",
        "PGA_CM/S^2": f"{np.abs(values).max():.6f}",
        "BASELINE_CORRECTION": "BASELINE REMOVED",
        "FILTER_TYPE": "BUTTERWORTH",
        "LOW_CUT_FREQUENCY_HZ": "0.100",
        "HIGH_CUT_FREQUENCY_HZ": "30.000",
        "HEADER_FORMAT": "DYNA 1.2",
        "DATA_TYPE": data_type,
        "PROCESSING": "manual (Paolucci et al., 2011)",
        "DATA_TIMESTAMP_YYYYMMDD_HHMMSS": "20170119_115411.000",
    }
    lines = [f"{k}: {v}" for k, v in head.items()]
    lines += [f"USER{k}:" for k in range(64 - len(lines))]
    path.write_text("\n".join(lines + [f"{v:.6f}" for v in values]) + "\n")
    return path


def test_esm_record_in_cm_s2_and_its_two_components(tmp_path):
    # the ESM / ITACA database's ASCII files, one a component: units from the header (cm/s^2), the
    # second file the motion along Y; their time steps must agree
    t = np.arange(0, 6, 0.005)
    env = np.sin(np.pi * t / t[-1]) ** 2  # starts and ends at rest
    east = 300.0 * env * np.sin(2 * np.pi * 1.2 * t)  # cm/s^2: 0.31 g
    north = 150.0 * env * np.sin(2 * np.pi * 2.1 * t)
    e = _esm_file(tmp_path / "IT.NRC..HNE.D.EMSC-20161030_0000029.ACC.MP.ASC", east)
    n = _esm_file(tmp_path / "IT.NRC..HNN.D.EMSC-20161030_0000029.ACC.MP.ASC", north, stream="HNN")
    one = read_accelerogram(e)
    assert one.dt == pytest.approx(0.005) and one.pga == pytest.approx(3.0, rel=0.02)
    assert np.all(one.displacement[:, 1] == 0)
    both = read_accelerogram(e, path_y=n)
    a = both.mean_acceleration(t[:-1:8])
    assert np.abs(a[:, 0]).max() == pytest.approx(3.0, rel=0.05)
    assert np.abs(a[:, 1]).max() == pytest.approx(1.5, rel=0.05)
    assert np.allclose(both.displacement[:, 0], one.displacement[:, 0])
    assert "HNN" in both.source and "HNE" in both.source
    with pytest.raises(InputError, match="time step 0.01 s differs"):
        read_accelerogram(e, path_y=_esm_file(tmp_path / "coarse.ASC", north[::2], dt=0.01))
    with pytest.raises(InputError, match="DATA_TYPE is 'VELOCITY'"):
        read_accelerogram(_esm_file(tmp_path / "v.ASC", east, data_type="VELOCITY"))
    with pytest.raises(InputError, match="NDATA = 5 but the file holds 1200"):
        read_accelerogram(_esm_file(tmp_path / "short.ASC", east, ndata=5))
    with pytest.raises(InputError, match="UNITS is 'counts'"):
        read_accelerogram(_esm_file(tmp_path / "c.ASC", east, units="counts"))
    with pytest.raises(InputError, match="--accelerogram-y .*add --accelerogram"):
        from calib_masonry.simulation.run import SimulationConfig

        SimulationConfig(accelerogram_y=n)


def test_a_record_whose_header_is_not_utf8_is_read_and_a_binary_file_refused(tmp_path):
    # a station's name in a Windows code page (ESM, PEER headers) is no reason to refuse the numbers
    t = np.arange(0, 3, 0.005)
    e = _esm_file(tmp_path / "cp.ASC", 200.0 * np.sin(np.pi * t / t[-1]) ** 2 * np.sin(7 * t))
    e.write_bytes(e.read_bytes().replace(b"STATION_NAME: NORCIA", "STATION_NAME: CITTÀ DI CASTELLO".encode("cp1252")))
    assert read_accelerogram(e).pga == pytest.approx(2.0, rel=0.05)
    b = tmp_path / "rec.csv"
    b.write_bytes(b"\x00\x01\xff\xfe" * 50)
    with pytest.raises(InputError, match="rec.csv: unreadable"):
        read_accelerogram(b)


def test_direction_turns_a_one_component_motion_and_is_refused_for_two(tmp_path):
    # simulate --direction: a record of one component (or the synthetic one with --components 1)
    # shakes along it, at the same peak; with two components there is nothing to turn
    from calib_masonry.simulation.run import SimulationConfig, motion_for

    t = np.arange(0, 4, 0.005)
    env = np.sin(np.pi * t / t[-1]) ** 2
    one = tmp_path / "one.csv"
    one.write_text("\n".join(f"{x:.3f},{0.2 * e * np.sin(2 * np.pi * 1.5 * x):.6f}" for x, e in zip(t, env)))
    along_x = motion_for(SimulationConfig(accelerogram=one, pga_g=0.3))
    turned = motion_for(SimulationConfig(accelerogram=one, pga_g=0.3, direction_deg=90.0))
    assert np.abs(turned.displacement[:, 0]).max() < 1e-12
    np.testing.assert_allclose(turned.displacement[:, 1], along_x.displacement[:, 0], rtol=1e-9, atol=1e-15)
    assert turned.pga == pytest.approx(0.3 * G, rel=1e-9) and "along 90 deg" in turned.source
    synthetic = motion_for(SimulationConfig(pga_g=0.3, components=1, direction_deg=30.0))
    ratio = synthetic.displacement[:, 1] / np.where(
        synthetic.displacement[:, 0] == 0, np.nan, synthetic.displacement[:, 0]
    )
    assert np.nanmax(np.abs(ratio - np.tan(np.radians(30.0)))) < 1e-9
    two = tmp_path / "two.csv"
    wave = env * np.sin(2 * np.pi * 2.0 * t)
    two.write_text("\n".join(f"{x:.3f},{0.1 * w:.6f},{-0.1 * w:.6f}" for x, w in zip(t, wave)))
    with pytest.raises(InputError, match="--direction 20: .*two horizontal components"):
        motion_for(SimulationConfig(accelerogram=two, pga_g=0.3, direction_deg=20.0))
    with pytest.raises(InputError, match="--direction 20: the synthetic motion has two .* add --components 1"):
        SimulationConfig(pga_g=0.3, direction_deg=20.0)
    with pytest.raises(InputError, match="--direction nan: give the motion's direction"):
        SimulationConfig(pga_g=0.3, components=1, direction_deg=float("nan"))
    with pytest.raises(InputError, match="--direction 20: --accelerogram-y"):
        SimulationConfig(accelerogram=one, accelerogram_y=one, direction_deg=20.0)
