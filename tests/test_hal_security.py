"""Zenoh's TLS, authentication and access control on the HAL, and exclusive control by claim (127.0.0.1 only).

The robot is a FakeRobot served in lock-step by a RobotServer in a thread of the test process; certificates
come from ``servotau certs``' code in a temporary directory. Lock-step makes "applied" observable: the robot
steps only on an accepted command, so a rejected command leaves ``ticks`` at 0.
"""

from __future__ import annotations

import json
import shutil
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import zenoh
from support.hal import free_port, query_status, wait_until

from servotau.apps.certs import CONTROLLER_CN, make_certs
from servotau.config import Section
from servotau.errors import ConfigError, HalError
from servotau.hal import ZenohBackend, keys
from servotau.hal.errors import ClaimRefused, RobotServoOff
from servotau.hal.robot.claim import claim_request
from servotau.hal.robot.config import ServerConfig
from servotau.hal.robot.firmware import SafetyConfig
from servotau.hal.robot.server import RobotServer
from servotau.hal.wire.protocol import encode_command
from servotau.hal.wire.security import AccessRole, Security, TlsConfig, security_from_section
from servotau.hal.wire.session import Session, zenoh_config
from servotau.simrobot.fake import FakeRobot

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="servotau certs needs openssl")
TIMEOUT = 10.0  # [s] safety net of the waits below, never the subject of a test


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    return make_certs(tmp_path_factory.mktemp("certs"), robot_hosts=["localhost", "127.0.0.1"],
                      controller_hosts=["localhost"], clients=["viewer"])


def _tls(identity, certs) -> TlsConfig:
    return TlsConfig(str(certs.ca), str(identity.certificate), str(identity.private_key))


@contextmanager
def serving(config: ServerConfig):
    """A FakeRobot served in a thread until the end of the block."""
    ready = threading.Event()
    server = RobotServer(FakeRobot(seed=0), config, on_ready=ready.set)
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    try:
        assert ready.wait(TIMEOUT), "robot server did not start"
        yield server
    finally:
        server.stop()
        thread.join(TIMEOUT)


def _wait(predicate) -> None:
    wait_until(predicate, TIMEOUT)


def _raw_commands(session: Session, n: int, *, attachment: bytes | None = None, matched: bool = True) -> None:
    """``n`` well-formed commands answering frame 0, put by a session that holds no claim, once its publisher
    matches the robot's subscriber (``matched=False``: access control may hide it; then after 0.2 s)."""
    q = FakeRobot(seed=0).read().q + 0.05
    pub = session.keep(session.z.declare_publisher(keys("fake").command))
    if matched:
        _wait(lambda: pub.matching_status.matching)
    else:
        time.sleep(0.2)
    for _ in range(n):
        pub.put(encode_command(0, 0.0, q), attachment=attachment)


def test_tls_and_access_control_only_the_controller_identity_drives(certs):
    """Mutual TLS + access control: an authenticated peer of another identity (a viewer) may read frames but its
    commands and its claim never reach the robot (none applied), even a claim spoofing the zid of another live
    session, in the payload and in the query's source_info (zenoh lets the querier fill that in); the controller's
    identity claims and drives."""
    port = free_port()
    ep = f"tls/127.0.0.1:{port}"
    roles = (AccessRole("controller", ("command", "claim", "operator", "observe"), cert_common_names=(CONTROLLER_CN,)),
             AccessRole("viewer", ("observe",), cert_common_names=("viewer",)))
    robot_sec = Security(tls=_tls(certs.robot, certs), access=roles)
    with serving(ServerConfig(listen=(ep,), security=robot_sec)) as server:
        viewer = Session(zenoh_config(connect=[ep], security=Security(tls=_tls(certs.clients[0], certs))))
        other = Session(zenoh_config(connect=[ep], security=Security(tls=_tls(certs.clients[0], certs))))
        try:
            frames = viewer.z.declare_subscriber(keys("fake").frame)
            _wait(lambda: frames.try_recv() is not None or server.status()["ticks"] > 0)
            _raw_commands(viewer, 50, matched=False)
            spoof = claim_request(str(other.z.zid()), "h", 1, "u")  # a live session with a transport to the robot
            claim = list(viewer.z.get(f"{keys('fake').prefix}/claim", payload=spoof, timeout=1.0,
                                      source_info=zenoh.SourceInfo(other.z.id, 0)))
            status = query_status(viewer)
            frames.undeclare()
        finally:
            viewer.close()
            other.close()
        assert claim == []  # the access control dropped the claim query
        assert server.status()["claims_refused"] == 0 and server.status()["claim_holder"] is None  # never reached
        assert status is not None and status["ticks"] == 0 and status["commands_accepted"] == 0 \
            and status["state"] == "WAITING"
        assert status["commands_not_claimer"] == 0 and status["commands_rejected"] == 0  # never reached the robot
        t0 = time.monotonic()
        with ZenohBackend("fake", connect=[ep], frame_timeout=TIMEOUT,
                          security=Security(tls=_tls(certs.controller, certs))) as b:
            t_connect = time.monotonic() - t0
            for _ in range(5):
                f = b.read()
                b.write({"J00": f.q[0] + 0.01})
            st = b.status()
        assert st["commands_accepted"] == 5 and st["claim_holder"].startswith(CONTROLLER_CN)
        print(f"TLS controller connect (session, claim, first frame): {t_connect * 1e3:.0f} ms")


def test_a_peer_without_a_certificate_cannot_connect(certs):
    """A plain-TCP or certificate-less peer gets no session to a TLS robot: no frame, no status."""
    port = free_port()
    ep = f"tls/127.0.0.1:{port}"
    roles = (AccessRole("controller", ("command", "claim", "observe"), cert_common_names=(CONTROLLER_CN,)),)
    with serving(ServerConfig(listen=(ep,), security=Security(tls=_tls(certs.robot, certs), access=roles))):
        with pytest.raises(HalError, match="no robot"):
            ZenohBackend("fake", connect=[f"tcp/127.0.0.1:{port}"], connect_timeout=0.5)


def test_a_claim_naming_the_holders_zid_gets_no_token():
    """The holder's zid is no secret (a refusal names the holder): a second claim naming it is refused like any
    other, and the claim's token is never handed out again."""
    from servotau.hal.robot.claim import ClaimTable, claim_request

    table, zid = ClaimTable(), "a1b2c3d4e5f60718"
    links = {zid: None, "99887766554433aa": None}
    first, event = table.handle(claim_request(zid, "ctl", 1, "op"), links, set(), 0.0)
    token = json.loads(first)["token"]
    again, event2 = table.handle(claim_request(zid, "thief", 2, "x"), links, set(), 1.0)
    reply = json.loads(again)
    assert event == "granted" and event2 is None and reply["granted"] is False and "token" not in reply
    assert table.token.hex() == token and table.claims_refused == 1


def test_second_claim_is_refused_and_unclaimed_commands_are_not_applied():
    """Loopback default: a second controller is refused naming the holder; a peer's commands without the claim's
    token are counted and never applied; after the release the next controller may claim."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    with serving(ServerConfig(listen=(ep,))) as server:
        peer = Session(zenoh_config(connect=[ep]))
        try:
            _raw_commands(peer, 20, attachment=b"0" * 16)
            _wait(lambda: server.status()["commands_not_claimer"] >= 20)
            assert server.status()["ticks"] == 0 and server.status()["commands_accepted"] == 0
            with ZenohBackend("fake", connect=[ep], frame_timeout=TIMEOUT) as b:
                f = b.read()
                b.write({"J00": f.q[0]})
                with pytest.raises(ClaimRefused, match=r"already controlled by .*pid .*Stop that controller"):
                    ZenohBackend("fake", connect=[ep], frame_timeout=TIMEOUT)
                _raw_commands(peer, 10)  # no attachment at all
                b.read()
                st = b.status()
            assert st["claims_refused"] == 1 and st["commands_accepted"] == 1
            _wait(lambda: server.status()["commands_not_claimer"] >= 30)
            assert server.status()["commands_not_claimer"] == 30
            with ZenohBackend("fake", connect=[ep], frame_timeout=TIMEOUT) as b2:  # released at close
                assert b2.status()["controller_alive"]
        finally:
            peer.close()


def test_the_claimers_own_session_ends_the_claim_not_a_foreign_token():
    """A foreign peer declaring the controller's zid-scoped liveliness token does not mask the controller's death:
    the robot watches the claimer's own transport, holds at once and frees the claim."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    with serving(ServerConfig(listen=(ep,))) as server:
        b = ZenohBackend("fake", connect=[ep], frame_timeout=TIMEOUT)
        f = b.read()
        b.write({"J00": f.q[0]})
        zid = str(b._session.z.zid())
        foreign = Session(zenoh_config(connect=[ep]))
        try:
            foreign.keep(foreign.z.liveliness().declare_token(f"{keys('fake').alive_controller}/{zid}"))
            foreign.keep(foreign.z.liveliness().declare_token(keys("fake").alive_controller))
            b._token = None  # no release: the session just goes, as a killed process's does
            b.close()
            _wait(lambda: server.status()["state"] == "HOLDING")
            st = server.status()
        finally:
            foreign.close()
    assert st["state"] == "HOLDING" and st["claim_holder"] is None and not st["controller_alive"]


def test_a_latched_servo_off_is_reported_at_connect():
    """A robot whose servos are off (latched) tells the next controller how to reset it, instead of a trip."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    no_rate_limit = SafetyConfig(max_velocity=1e6, max_acceleration=1e9)  # the 1 rad step reaches the servos
    with serving(ServerConfig(listen=(ep,), safety=no_rate_limit)) as server:
        with ZenohBackend("fake", connect=[ep], frame_timeout=TIMEOUT) as b:
            f = b.read()
            b.write(dict(zip(b.info.joint_names, np.asarray(f.q) + 1.0, strict=True)))  # > max_position_error
            _wait(lambda: server.status()["state"] == "SERVO_OFF")
        with pytest.raises(RobotServoOff, match=r"servos are off \(latched\): reset it with `servotau ctl reset`"):
            ZenohBackend("fake", connect=[ep], frame_timeout=TIMEOUT)
        assert server.status()["claim_holder"] is None  # released on the way out


# -- configuration errors: before any session opens ------------------------------------------------

def _server(data: dict) -> ServerConfig:
    return ServerConfig.from_section(Section(data, "hal.toml", "hal.server"))


def test_bad_security_config_names_the_field(certs, tmp_path):
    good = {"root_ca_certificate": str(certs.ca), "certificate": str(certs.robot.certificate),
            "private_key": str(certs.robot.private_key)}
    ctl = {"controller": {"cert_common_names": [CONTROLLER_CN], "may": ["command", "claim", "observe"]}}
    tls_ep = {"listen": ["tls/127.0.0.1:7447"]}
    cases = {
        "hal.server.tls.certificate' = '/nonexistent/robot.pem': expected a readable file (file not found)":
            {**tls_ep, "tls": {**good, "certificate": "/nonexistent/robot.pem"}, "access": ctl},
        "hal.server.tls.private_key' missing": {**tls_ep, "tls": {k: v for k, v in good.items() if k != "private_key"}},
        "needs tls settings": {**tls_ep},
        "leaves this machine without TLS": {"listen": ["tcp/0.0.0.0:7447"]},
        "leaves this machine without access control": {"listen": ["tls/0.0.0.0:7447"], "tls": good},
        "hal.server.access.controller.may' = ['command', 'fly']": {
            **tls_ep, "tls": good, "access": {"controller": {"cert_common_names": [CONTROLLER_CN],
                                                               "may": ["command", "fly"]}}},
        "hal.server.access.viewer.cert_common_names' missing": {
            **tls_ep, "tls": good, "access": {**ctl, "viewer": {"may": ["observe"]}}},
        "usernames ['mallory'] are not in": {
            **tls_ep, "tls": good, "auth": {"dictionary_file": str(_dictionary(tmp_path))},
            "access": {"controller": {"usernames": ["mallory"], "may": ["command"]}}},
        "a role that may \"command\"": {**tls_ep, "tls": good, "access": {"viewer": {
            "cert_common_names": ["viewer"], "may": ["observe"]}}},
        "hal.server.tlss'": {"tlss": good},
    }
    for expected, data in cases.items():
        with pytest.raises(ConfigError) as exc:
            _server(data)
        assert expected in str(exc.value), (expected, str(exc.value))


def _dictionary(tmp_path: Path) -> Path:
    p = tmp_path / "users.txt"
    p.write_text("controller:s3cret\n")
    return p


def test_user_password_authentication_and_acl_by_username(tmp_path):
    """usrpwd: the robot checks peers against its dictionary; the controller role is matched by user name, so
    the right password drives and a wrong one gets no session at all."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    pw, bad = tmp_path / "pw", tmp_path / "bad"
    pw.write_text("s3cret\n")
    bad.write_text("guess\n")
    srv = Section({"listen": [ep], "auth": {"dictionary_file": str(_dictionary(tmp_path))},
                   "access": {"controller": {"usernames": ["controller"],
                                             "may": ["command", "claim", "observe"]}}}, "hal.toml", "hal.server")
    with serving(ServerConfig.from_section(srv)):
        ctl = security_from_section(Section({"auth": {"user": "controller", "password_file": str(pw)}}, "h", "z"),
                                    robot_side=False)
        with ZenohBackend("fake", connect=[ep], frame_timeout=TIMEOUT, security=ctl) as b:
            f = b.read()
            b.write({"J00": f.q[0]})
            assert b.read().seq == f.seq + 1
        wrong = security_from_section(Section({"auth": {"user": "controller", "password_file": str(bad)}}, "h", "z"),
                                      robot_side=False)
        with pytest.raises(HalError, match="no robot"):
            ZenohBackend("fake", connect=[ep], connect_timeout=0.5, security=wrong)


def test_loopback_default_needs_no_security():
    """The shipped loopback default: plain TCP on 127.0.0.1, no certificates, no access control."""
    from servotau.hal.robot.config import server_config

    cfg = server_config("hal.toml")
    assert cfg.listen == ("tcp/127.0.0.1:7447",) and cfg.security == Security()


def test_controller_side_config_errors_name_the_field(certs, tmp_path):
    from servotau.hal.backends.zenoh import from_config

    tls = {"root_ca_certificate": str(certs.ca), "certificate": str(certs.controller.certificate),
           "private_key": str(certs.controller.private_key)}
    cases = {
        "field 'hal.zenoh.connect' = ['tls/127.0.0.1:1']: endpoint 'tls/127.0.0.1:1' needs tls settings":
            {"connect": ["tls/127.0.0.1:1"]},
        "field 'hal.zenoh.connect' = ['tcp/192.168.1.10:7447']: endpoint 'tcp/192.168.1.10:7447' leaves this machine "
        "without TLS": {"connect": ["tcp/192.168.1.10:7447"]},
        "field 'hal.zenoh.auth.password_file' = '/nonexistent/pw': expected a readable file (file not found)":
            {"connect": ["tls/127.0.0.1:1"], "tls": tls, "auth": {"user": "c", "password_file": "/nonexistent/pw"}},
        "field 'hal.zenoh.access'": {"connect": ["tls/127.0.0.1:1"], "tls": tls, "access": {}},
    }
    for expected, data in cases.items():
        with pytest.raises(ConfigError) as exc:
            from_config(Section({"zenoh": data}, "hal.toml", "hal"))
        assert expected in str(exc.value), (expected, str(exc.value))


def test_the_robot_process_refuses_a_network_endpoint_without_security(certs, capsys):
    """``python -m servotau.hal`` checks its endpoints before it builds or serves the robot."""
    from servotau.hal.robot.cli import main

    assert main(["--robot", "servotau.simrobot.fake:FakeRobot", "--listen", "tcp/0.0.0.0:7447"]) == 2
    assert "endpoint 'tcp/0.0.0.0:7447' leaves this machine without TLS" in capsys.readouterr().err
    with pytest.raises(HalError, match="without access control"):  # the session config itself checks it too
        zenoh_config(listen=["tls/0.0.0.0:7447"], security=Security(tls=_tls(certs.robot, certs)),
                     key_prefix="servotau/v1/x")


def test_access_by_network_interface_and_a_role_that_may_only_observe():
    """Roles by interface on plain loopback: the controller role drives; an observe-only role is not answered."""
    for may, drives in ((("command", "claim", "observe"), True), (("observe",), False)):
        port = free_port()
        ep = f"tcp/127.0.0.1:{port}"
        roles = (AccessRole("local", may, interfaces=("lo",)), AccessRole("nobody", ("command",), interfaces=("x9",)))
        with serving(ServerConfig(listen=(ep,), security=Security(access=roles))):
            if drives:
                with ZenohBackend("fake", connect=[ep], frame_timeout=TIMEOUT) as b:
                    f = b.read()
                    b.write({"J00": f.q[0]})
                    assert b.read().seq == f.seq + 1
            else:
                with pytest.raises(HalError, match="did not answer the claim.*access control"):
                    ZenohBackend("fake", connect=[ep], connect_timeout=1.0)


def test_tls_settings_built_in_python_are_checked_too(certs):
    with pytest.raises(HalError, match="TlsConfig.private_key: file not found: /nonexistent/key.pem"):
        TlsConfig(str(certs.ca), str(certs.robot.certificate), "/nonexistent/key.pem")
    with pytest.raises(HalError, match=r"may = \['drive'\]: expected a non-empty list among"):
        AccessRole("x", ("drive",), cert_common_names=("a",))


def test_a_claim_needs_a_session_the_robot_can_watch():
    """A claim naming a session the robot cannot watch (no transport, no token) is refused, so no claim outlives
    the session behind it; a peer's own zid is granted, and the claim ends when that session closes."""
    from servotau.hal.robot.claim import claim_key, claim_request

    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    with serving(ServerConfig(listen=(ep,))) as server:
        peer = Session(zenoh_config(connect=[ep]))
        try:
            def claim(zid: str) -> dict:
                r = next(iter(peer.z.get(claim_key(keys("fake").prefix), payload=claim_request(zid, "h", 1, "u"),
                                         timeout=10.0)))  # [s] a safety net: the first reply ends the wait
                return json.loads(r.ok.payload.to_bytes())

            forged = claim("abcdef")
            assert not forged["granted"] and "neither a transport to the robot nor" in forged["error"]
            assert claim(str(peer.z.zid()))["granted"]
            assert server.status()["claim_holder"] is not None
        finally:
            peer.close()
        _wait(lambda: server.status()["claim_holder"] is None)
        assert server.status()["claim_holder"] is None and server.status()["claims_refused"] == 1


def test_a_role_needs_every_kind_of_name_it_gives(certs):
    """The controller's certificate on the wrong interface matches no role: no session reaches the robot."""
    port = free_port()
    ep = f"tls/127.0.0.1:{port}"
    roles = (AccessRole("controller", ("command", "claim", "observe"), cert_common_names=(CONTROLLER_CN,),
                        interfaces=("x9",)),)
    with serving(ServerConfig(listen=(ep,), security=Security(tls=_tls(certs.robot, certs), access=roles))):
        with pytest.raises(HalError, match="no robot"):
            ZenohBackend("fake", connect=[ep], connect_timeout=0.5,
                         security=Security(tls=_tls(certs.controller, certs)))


@pytest.mark.parametrize("endpoint, loopback", [
    ("tcp/127.0.0.1:7447", True), ("tls/localhost:7447", True), ("tcp/[::1]:7447", True),
    ("unixsock-stream//tmp/zenoh.sock", True), ("tcp/0.0.0.0:7447", False), ("tcp/[::]:7447", False),
    ("tls/robot.lan:7447", False), ("tcp/localhost.example.com:7447", False), ("udp/192.168.1.10:7447", False)])
def test_loopback_endpoints(endpoint, loopback):
    from servotau.hal.wire.security import is_loopback

    assert is_loopback(endpoint) is loopback


def test_a_claim_the_robot_cannot_yet_watch_is_retried_a_bounded_number_of_times():
    """Through a router the claimer's token may reach the robot after its claim: the controller claims again (the
    robot's real ClaimTable answers), and after CLAIM_ATTEMPTS refusals it gives up naming the cause; any other
    refusal is not retried."""
    from servotau.hal.errors import ClaimUnseen
    from servotau.hal.robot.claim import CLAIM_ATTEMPTS, ClaimTable, claim_request, claim_with_retry

    zid, request = "a1b2c3d4e5f60718", claim_request("a1b2c3d4e5f60718", "ctl", 1, "op")
    for seen_after in (2, None):  # the token arrives before the third claim; never
        table, tokens, asked, waits = ClaimTable(), set(), [], []

        def ask(timeout, table=table, tokens=tokens, asked=asked, seen_after=seen_after):
            asked.append(timeout)
            if len(asked) > (seen_after if seen_after is not None else 99):
                tokens.add(zid)
            return table.handle(request, {}, tokens, 0.0)[0]

        if seen_after is not None:
            token = claim_with_retry(ask, "fake", 1.0, sleep=waits.append)
            assert token == table.token and len(asked) == 3 and waits == [0.02, 0.04]
        else:
            with pytest.raises(ClaimRefused, match=f"{CLAIM_ATTEMPTS} claims over .*router forwards liveliness") as e:
                claim_with_retry(ask, "fake", 1.0, sleep=waits.append)
            assert not isinstance(e.value, ClaimUnseen) and len(asked) == CLAIM_ATTEMPTS
            assert table.holder is None and table.claims_refused == CLAIM_ATTEMPTS
    held = ClaimTable()
    held.handle(claim_request("99887766554433aa", "other", 2, "x"), {"99887766554433aa": None}, set(), 0.0)
    asked = []
    with pytest.raises(ClaimRefused, match="already controlled"):
        claim_with_retry(lambda t: asked.append(t) or held.handle(request, {zid: None}, set(), 1.0)[0], "fake", 1.0)
    assert len(asked) == 1  # held by another controller: no retry
    assert claim_with_retry(lambda t: None, "fake", 1.0) is None  # no answer: the caller's timeout error
