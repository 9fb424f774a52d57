"""The page on the LAN: HTTPS with a self-signed certificate made on first use, and a token
without which nothing is served (but the static files that say how to get in)."""

from __future__ import annotations

import argparse
import ssl
import stat
import threading

import cv2
import httpx
import numpy as np
import pytest

from asibot.bus import Bus
from asibot.testing import free_port, memory_bus, wait_until
from asibot.web import service


def args(tmp_path, **kw) -> argparse.Namespace:
    base = dict(host=None, port=free_port(), data=tmp_path, lan=False, new_token=False)
    base.update(kw)
    return argparse.Namespace(**base)


def anonymous_refused(url: str, context) -> bool:
    return httpx.get(url, verify=context, timeout=5).status_code == 401


def test_serving_beyond_this_machine_needs_lan_mode(tmp_path, monkeypatch):
    monkeypatch.delenv("ASIBOT_WEB_HOST", raising=False)
    with memory_bus("lan-refuse") as ep, Bus("web", ep) as bus:
        with pytest.raises(ValueError, match="--lan"):
            service.build(bus, args(tmp_path, host="0.0.0.0"))
        with pytest.raises(ValueError, match="--new-token"):
            service.build(bus, args(tmp_path, new_token=True))


def read_qr(image) -> str:
    """The text of a QR code as a phone's camera reads it. OpenCV's classic detector misses about
    one valid code in fifty (measured on random tokens), and its ArUco-based one reads those."""
    return cv2.QRCodeDetector().detectAndDecode(image)[0] or cv2.QRCodeDetectorAruco().detectAndDecode(image)[0]


def test_lan_mode_serves_https_and_only_with_the_token(tmp_path, capsys):
    with memory_bus("lan") as ep, Bus("web", ep) as bus:
        a = args(tmp_path, host="127.0.0.1", lan=True)
        svc = service.build(bus, a)
        printed = capsys.readouterr().out
        assert "?token=" in printed and "only now" in printed
        token = printed.split("?token=")[1].split()[0]
        folder = tmp_path / ".lan"
        assert stat.S_IMODE((folder / "key.pem").stat().st_mode) == 0o600
        stop = threading.Event()
        runner = threading.Thread(target=svc.run, args=(stop,), daemon=True)
        runner.start()
        try:
            context = ssl.create_default_context(cafile=str(folder / "cert.pem"))
            url = f"https://127.0.0.1:{a.port}"

            def up() -> bool:
                try:
                    return httpx.get(url + "/static/css/app.css", verify=context, timeout=2).status_code == 200
                except httpx.HTTPError:
                    return False
            wait_until(up, timeout=15, interval=0.2)
            with httpx.Client(verify=context, timeout=5) as anonymous:
                refused = anonymous.get(url + "/api/robots")
                assert refused.status_code == 401 and "token" in refused.text
                assert anonymous.get(url + "/?token=wrong").status_code == 401
                assert anonymous.post(url + "/api/estop").status_code == 401
            assert anonymous_refused(url + "/api/phone", context)       # the address holds the token
            with httpx.Client(verify=context, timeout=5) as phone:
                first = phone.get(url + f"/?token={token}", follow_redirects=False)
                assert first.status_code == 303 and "HttpOnly" in first.headers["set-cookie"]
                assert phone.get(url + "/api/robots").status_code == 200
                # Home's QR code: a camera reads the address that lets the next phone in
                how = phone.get(url + "/api/phone").json()
                assert how["lan"] and all(u.endswith(f"?token={token}") and u.startswith("https://") for u in how["urls"])
                png = phone.get(url + "/api/phone/qr.png")
                assert png.headers["content-type"] == "image/png"
                image = cv2.imdecode(np.frombuffer(png.content, np.uint8), cv2.IMREAD_GRAYSCALE)
                assert read_qr(image) == how["urls"][0]
            assert httpx.get(url + "/api/robots", headers={"Authorization": f"Bearer {token}"},
                             verify=context).status_code == 200
            with pytest.raises(httpx.HTTPError):
                httpx.get(url + "/api/robots", timeout=5)   # the system's CAs do not know this certificate
        finally:
            stop.set()
            runner.join(10)
            svc.close()
        # The second start keeps the certificate and the token, and does not print the token again.
        again = service.build(bus, args(tmp_path, host="127.0.0.1", lan=True))
        assert "?token=" not in capsys.readouterr().out
        again.close()
        renewed = service.build(bus, args(tmp_path, host="127.0.0.1", lan=True, new_token=True))
        assert "?token=" in capsys.readouterr().out and (folder / "token").read_text() != token
        renewed.close()


def test_on_this_machine_only_home_says_how_to_reach_a_phone(tmp_path):
    from fastapi.testclient import TestClient
    with memory_bus("lan-none") as ep, Bus("web", ep) as bus:
        svc = service.build(bus, args(tmp_path, host="127.0.0.1"))
        try:
            client = TestClient(svc.app, base_url="http://127.0.0.1:8080")
            how = client.get("/api/phone").json()
            assert how == {"lan": False, "urls": [], "text": how["text"]} and "--lan" in how["text"]
            refused = client.get("/api/phone/qr.png")
            assert refused.status_code == 503 and "--lan" in refused.json()["message"]
        finally:
            svc.close()
