"""dynprop's AEM and APM read by Orekit's own parsers (``orekit-jpype``, a JVM).

Run by test_aem_orekit.py in a pytest process of its own: a JVM started inside the
suite's process would hang every later test that forks (the JVM's threads hold locks
the forked child inherits locked), so it never starts there.

Orekit (``ParserBuilder().buildAemParser()``) must parse the file, its metadata must
say what dynprop meant, and the attitude it interpolates at random epochs must be
dynprop's to the printed precision.  Orekit also checks the two frame compositions
independently: its LVLH_ROTATING frame (built from the orbit dynprop flies) composed
with the orbit-frame AEM gives the inertial AEM, and its MOD frame (IERS 1996, Lieske
precession in the ψ_A, ω_A, χ_A form) is ``ephemeris.precession_matrix``.

tests/fixtures/orekit-data holds only what the parse needs (found by trying):
``tai-utc.dat``, the USNO table of TAI − UTC (leap seconds to 2017), for the UTC
epochs; and ``linux_p1550p2650.440``, the two header records (constants only, 16 kB)
of JPL's DE440 binary ephemeris, because ``CENTER_NAME = EARTH`` makes Orekit build
the Earth body, whose GM it reads from there.  No position is ever asked for.

Without ``orekit-jpype`` (pip) or a JVM (Debian's ``default-jre-headless``) the tests
skip, naming what is missing, unless DYNPROP_OREKIT_REQUIRED is set, where they fail.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from scenarios.files import aem
from scenarios.files.aem import AemMeta
from sim import ephemeris
from sim.frames import GeoOrbit, quat_from_dcm, quat_multiply
from sim.inertial import inertial_quaternions, orbit_frame_quaternions

from .test_aem import frame_bias, in_frame_bias_frame

DATA = Path(__file__).resolve().parents[1] / "fixtures" / "orekit-data"
EPOCH = datetime(2026, 3, 20, 12, tzinfo=UTC)
META = AemMeta("GOES-NEXT", "2026-000A", interpolation_degree=7)
READ = 1.5e-12     # 12 printed decimals, renormalised
ORBIT = GeoOrbit()


def _missing(message: str):
    if os.environ.get("DYNPROP_OREKIT_REQUIRED"):
        pytest.fail(message + " -- DYNPROP_OREKIT_REQUIRED is set", pytrace=False)
    pytest.skip(message)


@pytest.fixture(scope="module")
def orekit():
    if importlib.util.find_spec("orekit_jpype") is None:
        _missing("orekit-jpype is not installed (pip install orekit-jpype)")
    if not (shutil.which("java") or os.environ.get("JAVA_HOME")):
        _missing("no JVM: install Debian's default-jre-headless")
    import orekit_jpype
    try:
        orekit_jpype.initVM()
    except Exception as exc:  # noqa: BLE001 -- any JVM start failure is a missing JVM
        _missing(f"the JVM would not start ({exc}): install Debian's default-jre-headless")
    from java.io import File
    from org.orekit.data import DataContext, DirectoryCrawler
    DataContext.getDefault().getDataProvidersManager().addProvider(
        DirectoryCrawler(File(str(DATA))))
    import org.orekit as o
    return o


def angles(t):
    return (3e-3 * np.sin(t / 5000.0), -2e-3 * np.cos(t / 7000.0), 5e-3 * np.sin(t / 9000.0))


def grid():
    t = np.arange(0.0, 2 * 86400 + 1, 64.0)
    return t[(t < 20_000) | (t > 20_640)]        # a dropout: two segments


def parse(o, path):
    from org.orekit.data import DataSource
    from org.orekit.files.ccsds.ndm import ParserBuilder
    return ParserBuilder().buildAemParser().parseMessage(DataSource(str(path)))


def start(o):
    from org.orekit.time import AbsoluteDate, TimeScalesFactory
    return AbsoluteDate("2026-03-20T12:00:00", TimeScalesFactory.getUTC())


def q_of(rotation):
    """Orekit's Rotation (q0 scalar) as dynprop's scalar-last quaternion."""
    return np.array([rotation.getQ1(), rotation.getQ2(), rotation.getQ3(), rotation.getQ0()])


def present(value):
    """A Java Optional's value (Orekit's development API) or the value itself (13.1)."""
    return value.get() if hasattr(value, "isPresent") else value


def same_rotation(a, b):
    return np.minimum(np.abs(a - b).max(axis=-1), np.abs(a + b).max(axis=-1)).max()


def random_epochs(segments, per_segment=40):
    rng = np.random.default_rng(7)
    return [np.sort(rng.uniform(*s.seconds_since(EPOCH)[[0, -1]], per_segment))
            for s in segments]


@pytest.mark.parametrize("version", ["2.0", "1.0"])
def test_orekit_reads_the_inertial_aem_and_interpolates_dynprop_attitude(orekit, tmp_path,
                                                                        version):
    from org.orekit.frames import FramesFactory
    t = grid()
    q = inertial_quaternions(t, *angles(t), ORBIT, EPOCH)
    path = tmp_path / "estimate.aem"
    aem.write_aem(path, t, q, AemMeta("GOES-NEXT", "2026-000A", version=version),
                  epoch=EPOCH, cadence_s=64.0)
    message = parse(orekit, path)
    ours = aem.read_aem(path)
    header = message.getHeader()
    assert header.getFormatVersion() == float(version)
    assert header.getOriginator() == "DYNPROP"
    assert message.getSegments().size() == len(ours) == 2
    t0, eme = start(orekit), FramesFactory.getEME2000()
    for segment, mine, epochs in zip(message.getSegments(), ours, random_epochs(ours),
                                     strict=True):
        m = segment.getMetadata()
        ends = m.getEndpoints()
        assert (m.getObjectName(), m.getObjectID(), m.getCenter().getName()) == \
            ("GOES-NEXT", "2026-000A", "EARTH")
        assert (ends.getFrameA().getName(), ends.getFrameB().getName()) == ("EME2000", "SC_BODY_1")
        assert ends.isA2b() and not m.isFirst() and ends.isExternal2SpacecraftBody()
        assert str(m.getAttitudeType()) == "QUATERNION" and str(m.getTimeSystem()) == "UTC"
        assert present(m.getInterpolationMethod()) == "LAGRANGE"
        assert m.getInterpolationDegree() == 7
        seconds = mine.seconds_since(EPOCH)
        assert m.getStartTime().durationFrom(t0) == seconds[0]
        assert m.getStopTime().durationFrom(t0) == seconds[-1]
        assert segment.getAngularCoordinates().size() == len(seconds)
        provider = segment.getAttitudeProvider()
        theirs = np.array([q_of(provider.getAttitude(None, t0.shiftedBy(float(s)), eme)
                                .getRotation()) for s in epochs])
        stamps = np.datetime64("2026-03-20T12:00:00") + np.round(epochs * 1e9).astype(
            "timedelta64[ns]")
        assert same_rotation(theirs, mine.interpolate(stamps)) < READ
        assert same_rotation(theirs, inertial_quaternions(epochs, *angles(epochs), ORBIT,
                                                              EPOCH)) < 2 * READ


def test_orekit_composes_the_orbit_frame_aem_into_the_inertial_one(orekit, tmp_path):
    """Orekit builds LVLH_ROTATING from the orbit (the satellite of ``GeoOrbit``, in
    EME2000 through ``ephemeris.precession_matrix``) and composes it with the file's q_BR."""
    from jpype import JImplements, JOverride
    from org.hipparchus.geometry.euclidean.threed import Vector3D
    from org.orekit.frames import FramesFactory
    from org.orekit.utils import TimeStampedPVCoordinates
    t0, eme = start(orekit), FramesFactory.getEME2000()
    jd0 = ephemeris.julian_date(EPOCH)

    @JImplements("org.orekit.utils.PVCoordinatesProvider")
    class Satellite:
        @JOverride
        def getPVCoordinates(self, date, frame):
            assert frame.getName() == "EME2000"
            s = date.durationFrom(t0)
            r, v = ORBIT.position_velocity(s, ephemeris.gmst_rad(jd0))
            p = ephemeris.precession_matrix(jd0 + s / 86400.0)
            return TimeStampedPVCoordinates(date, Vector3D(*map(float, p.T @ r)),
                                            Vector3D(*map(float, p.T @ v)))

    t = grid()
    path = tmp_path / "orbit.aem"
    aem.write_aem(path, t, orbit_frame_quaternions(*angles(t)),
                  AemMeta("GOES-NEXT", "2026-000A", ref_frame_a="LVLH_ROTATING"),
                  epoch=EPOCH, cadence_s=64.0)
    message = parse(orekit, path)
    ours = aem.read_aem(path)
    for segment, mine, epochs in zip(message.getSegments(), ours, random_epochs(ours),
                                     strict=True):
        frame = segment.getMetadata().getEndpoints().getFrameA()
        assert frame.getName() == "LVLH_ROTATING"
        assert str(present(frame.asOrbitRelativeFrame()).getLofType()) == "LVLH_CCSDS"
        provider = segment.getAttitudeProvider()
        theirs = np.array([q_of(provider.getAttitude(Satellite(), t0.shiftedBy(float(s)), eme)
                                .getRotation()) for s in epochs])
        stamps = np.datetime64("2026-03-20T12:00:00") + np.round(epochs * 1e9).astype(
            "timedelta64[ns]")
        c_rj = ORBIT.orbit_frame(epochs, ephemeris.gmst_rad(jd0)) @ ephemeris.precession_matrix(
            jd0 + epochs / 86400.0)
        composed = quat_multiply(mine.interpolate(stamps), quat_from_dcm(c_rj))
        assert same_rotation(theirs, composed) < READ
        inertial = inertial_quaternions(epochs, *angles(epochs), ORBIT, EPOCH)
        assert same_rotation(theirs, inertial) < 2 * READ


def test_orekit_reads_the_apm(orekit, tmp_path):
    from org.orekit.data import DataSource
    from org.orekit.files.ccsds.ndm import ParserBuilder
    from org.orekit.frames import FramesFactory
    q = inertial_quaternions([100.0], *angles(np.array([100.0])), ORBIT, EPOCH)[0]
    aem.write_apm(tmp_path / "a.apm", "2026-03-20T12:01:40Z", q, META)
    apm = ParserBuilder().buildApmParser().parseMessage(DataSource(str(tmp_path / "a.apm")))
    assert apm.getMetadata().getObjectName() == "GOES-NEXT"
    assert apm.getData().getEpoch().durationFrom(start(orekit)) == 100.0
    block = apm.getData().getQuaternionBlock()
    ends = block.getEndpoints()
    assert (ends.getFrameA().getName(), ends.getFrameB().getName()) == ("EME2000", "SC_BODY_1")
    rotation = apm.getAttitude(FramesFactory.getEME2000(), None).getRotation()
    assert same_rotation(q_of(rotation)[None], q[None]) < READ


def test_the_hand_written_frame_bias_is_orekits_gcrf(orekit):
    """test_aem.frame_bias (IERS's B, written out) against Orekit's GCRF → EME2000: the
    same IAU 2000 offsets, Orekit forming ξ0 from Δψ sin ε0 (7e-13 rad apart)."""
    from org.orekit.frames import FramesFactory
    rotation = FramesFactory.getGCRF().getTransformTo(FramesFactory.getEME2000(),
                                                      start(orekit)).getRotation()
    theirs = np.array([list(row) for row in rotation.getMatrix()])
    assert np.abs(theirs - frame_bias()).max() < 2e-12
    assert np.abs(theirs - np.eye(3)).max() > 5e-8       # the bias, not the identity


@pytest.mark.parametrize("label", ["J2000", "GCRF"])
def test_orekit_reads_the_frame_bias_frames_as_the_tests_write_them(orekit, tmp_path, label):
    """test_export's J2000 and GCRF AEMs (``test_aem.in_frame_bias_frame``) read by Orekit
    in EME2000 give the C_{B←EME2000} they were made from, to the printing: Orekit takes
    J2000 as EME2000 and composes GCRF with its own bias.  ICRF (the GCRF's axes) is not
    asked: Orekit's ICRF is the barycentre's, and the transform wants the Earth's
    position, which the fixture's DE440 headers do not hold."""
    from org.orekit.frames import FramesFactory
    t = grid()[:60]
    q = inertial_quaternions(t, *angles(t), ORBIT, EPOCH)
    path = tmp_path / f"{label}.aem"
    aem.write_aem(path, t, in_frame_bias_frame(q, label), META, epoch=EPOCH, cadence_s=64.0)
    path.write_text(path.read_text().replace("REF_FRAME_A = EME2000", f"REF_FRAME_A = {label}"))
    (segment,) = parse(orekit, path).getSegments()
    assert segment.getMetadata().getEndpoints().getFrameA().getName() == label
    provider, t0 = segment.getAttitudeProvider(), start(orekit)
    theirs = np.array([q_of(provider.getAttitude(None, t0.shiftedBy(float(s)),
                                                 FramesFactory.getEME2000()).getRotation())
                       for s in t])
    assert same_rotation(theirs, q) < READ


def test_precession_matches_orekits_mod_frame(orekit):
    """Orekit's MOD (IERS 1996, no EOP) under EME2000 is Lieske's precession in its
    four-angle form: the same model, truncated differently, to ~1e-10 rad by 2050."""
    from org.orekit.frames import FramesFactory
    from org.orekit.time import AbsoluteDate, TimeScalesFactory
    mod, eme, tt = FramesFactory.getMOD(False), FramesFactory.getEME2000(), \
        TimeScalesFactory.getTT()
    for date in ("2000-01-01T12:00:00", "2026-03-20T12:00:00", "2050-01-01T00:00:00"):
        rotation = eme.getTransformTo(mod, AbsoluteDate(date, tt)).getRotation()
        theirs = np.array([list(row) for row in rotation.getMatrix()])
        jd = ephemeris.julian_date(datetime.fromisoformat(date).replace(tzinfo=UTC))
        assert np.abs(theirs - ephemeris.precession_matrix(jd)).max() < 1.5e-10, date
