from __future__ import annotations

import numpy as np
import pytest

from drivers.base import CartesianCommand, FtSamples
from drivers.base.guards import requires_open
from drivers.errors import NotConnectedError
from drivers.fri.types import CmdFlags, ControlMode, FriCommand, FriMeasurement


def test_hold_mirrors_the_krc() -> None:
    m = FriMeasurement(control=ControlMode.CART_IMPEDANCE)
    m.cmd_jnt_pos[:] = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]
    m.cmd_jnt_pos_fri_offset[:] = 0.01
    m.cmd_cart_pos[:3, 3] = [0.6, 0.0, 0.5]
    c = FriCommand.hold(m)
    assert c.flags == CmdFlags.JNTPOS | CmdFlags.CARTPOS
    np.testing.assert_allclose(c.jnt_pos, m.cmd_jnt_pos + 0.01)
    np.testing.assert_array_equal(c.cart_pos, m.cmd_cart_pos)
    assert c.cart_pos is not m.cmd_cart_pos


def test_flag_values_match_fricomm() -> None:
    assert int(CmdFlags.JNTPOS) == 0x0001
    assert int(CmdFlags.TCPFT) == 0x0400
    assert int(CmdFlags.CARTSTIFF | CmdFlags.CARTDAMP) == 0x3000


def test_default_arrays_are_not_shared() -> None:
    a, b = FriCommand(), FriCommand()
    a.add_tcp_ft[2] = 1.0
    assert b.add_tcp_ft[2] == 0.0


def test_ft_samples_concat() -> None:
    a = FtSamples(time_ns=np.array([1, 2]), seq=np.array([0, 1]), wrench=np.ones((2, 6)),
                  status=np.zeros(2, dtype=np.uint32))
    b = FtSamples(time_ns=np.array([3]), seq=np.array([2]), wrench=np.zeros((1, 6)),
                  status=np.array([0x20000], dtype=np.uint32))
    c = FtSamples.concat([a, b])
    assert len(c) == 3
    assert list(c.time_ns) == [1, 2, 3]
    assert c.status[2] == 0x20000
    assert len(FtSamples.concat([])) == 0


def test_cartesian_command_copy_is_deep() -> None:
    a = CartesianCommand()
    b = a.copy()
    for name in ("pose_m", "stiffness_npm_nmprad", "damping_ratio", "wrench_n_nm"):
        assert getattr(a, name) is not getattr(b, name)
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


class _Device:
    def __init__(self) -> None:
        self.is_open = False

    @requires_open("test device")
    def read(self, x: int) -> int:
        return x + 1


def test_requires_open_names_device_and_method() -> None:
    d = _Device()
    with pytest.raises(NotConnectedError, match=r"^test device: read\(\) before connect/start$"):
        d.read(1)
    d.is_open = True
    assert d.read(1) == 2


def test_ground_truth_messages_name_each_body_and_unattached_site() -> None:
    """The truth's messages: the truth itself, each body, each site not fixed on a body
    (as a frame of its pose), under the prefix; the names kept per prefix do not leak
    from one prefix or truth to another."""
    from drivers.base.types import AttachedFrame, BodyTruth, GroundTruth

    for pre in ("/sim", "/other", "/sim"):
        bodies = {"target": BodyTruth(), "base": BodyTruth(mass_kg=3.0)}
        sites = {"mouth": np.eye(4) * 2.0, "tcp": np.eye(4) * 3.0, "fixed": np.eye(4)}
        attached = {"fixed": AttachedFrame("target", np.eye(4))}
        truth = GroundTruth(bodies=bodies, sites=sites, attached=attached, topic_prefix=pre)
        got = truth.messages()
        assert [t for t, _ in got] == [f"{pre}/truth", f"{pre}/body/target", f"{pre}/body/base",
                                       f"{pre}/site/mouth", f"{pre}/site/tcp"]
        assert got[0][1] is truth and got[1][1] is bodies["target"] and got[2][1] is bodies["base"]
        assert got[3][1].pose is sites["mouth"]
        assert got[4][1].pose is sites["tcp"]
        bare = GroundTruth(bodies={"b": BodyTruth()}, topic_prefix=pre)
        assert [t for t, _ in bare.messages()] == [f"{pre}/truth", f"{pre}/body/b"]
