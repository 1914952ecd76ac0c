"""servotau certs: a development CA and certificates for two hosts, and the hal.toml lines that use them."""

from __future__ import annotations

import shutil
import stat
import subprocess
import tomllib

import pytest

from servotau.cli import main
from servotau.config import Section
from servotau.hal.robot.config import ServerConfig
from servotau.hal.wire.security import security_from_section

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="servotau certs needs openssl")


def _text(cert) -> str:
    return subprocess.run(["openssl", "x509", "-in", str(cert), "-noout", "-text"], capture_output=True, text=True,
                          check=True).stdout


def test_certs_for_two_hosts_and_the_printed_config_validates(tmp_path, capsys):
    d = tmp_path / "certs"
    assert main(["certs", str(d), "--robot-host", "robot.lan", "--robot-host", "192.168.1.10",
                 "--controller-host", "ctl.lan", "--client", "viewer"]) == 0
    out = capsys.readouterr().out
    for stem in ("ca", "robot", "controller", "viewer"):
        assert stat.S_IMODE((d / f"{stem}-key.pem").stat().st_mode) == 0o600
        assert (d / f"{stem}.pem").exists()
    robot = _text(d / "robot.pem")
    assert "CN = servotau-robot" in robot and "DNS:robot.lan" in robot and "IP Address:192.168.1.10" in robot
    assert "TLS Web Client Authentication" in _text(d / "controller.pem")
    verify = subprocess.run(["openssl", "verify", "-CAfile", str(d / "ca.pem"), str(d / "robot.pem"),
                             str(d / "controller.pem")], capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr
    toml = tomllib.loads(out.split("\n", 2)[2])  # after the summary line
    server = ServerConfig.from_section(Section(toml["hal"]["server"], "printed", "hal.server"))
    assert server.listen == ("tls/robot.lan:7447",) and server.security.access[0].cert_common_names == (
        "servotau-controller",)
    ctl = security_from_section(Section(toml["hal"]["zenoh"], "printed", "hal.zenoh"), robot_side=False)
    assert ctl.tls.certificate == str(d / "controller.pem")


def test_certs_refuse_to_overwrite_and_bad_hosts(tmp_path, capsys):
    assert main(["certs", str(tmp_path)]) == 0
    assert main(["certs", str(tmp_path)]) == 2
    assert "exists: expected an empty directory (or --force to replace)" in capsys.readouterr().err
    assert main(["certs", str(tmp_path / "x"), "--robot-host", "bad host!"]) == 2
    assert "host 'bad host!': expected a host name or an IP address" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()  # checked before anything is written
