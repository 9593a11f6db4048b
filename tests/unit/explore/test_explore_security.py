"""Hostile requests against the explorer (uwlab/explore/security.py, inputs.check_files): none may succeed.

Each request is one a web page the user visits, a DNS-rebinding attacker or a curious client could send; the
assertions check that it is refused, that the refusal says nothing about the machine's files and repeats nothing of
the request, and that the user's own page still works.
"""

from __future__ import annotations

import asyncio
import json
import os
from pathlib import Path
from urllib.parse import quote, urlsplit

import pytest
from starlette.testclient import TestClient

from tests.support.explorer_process import SECRET as SECRET_LINE
from tests.support.explorer_process import file_probes, plant_secrets
from tests.support.paths import CONFIGS, EXAMPLE
from uwlab.explore.app import create_app
from uwlab.explore.catalog import Catalog
from uwlab.explore.inputs import OUTSIDE_ROOTS, load_served
from uwlab.explore.security import Access, Guard
from uwlab.model import data

LOCAL = "http://127.0.0.1:8050"
TOKEN = "s3cret-token-for-tests"
SECRET = "SECRET-TOKEN-abc123, hunter2"


def client(access: Access | None = None, served=None) -> TestClient:
    return TestClient(create_app(served or load_served(EXAMPLE), Catalog(), access), base_url=LOCAL)


def browser_post(c: TestClient, path: str, body: dict) -> object:
    """A same-origin POST as the page's script sends it: Origin, JSON and the XSRF cookie repeated in a header."""
    c.get("/api/schema")
    return c.post(path, json=body, headers={"Origin": LOCAL, "X-XSRF-Token": c.cookies.get("_xsrf", "")})


@pytest.fixture
def secret_file(tmp_path):
    path = tmp_path / "secret.csv"
    path.write_text(f"{SECRET}\n400,1\n")
    return path


# ---- the user's own requests still work ---------------------------------------------------------------------


def test_the_page_and_its_api_work_from_the_page():
    with client() as c:
        page = c.get("/")
        assert page.status_code == 200 and "explorer.js" in page.text
        answer = browser_post(c, "/api/design", {"set": {"lens.f_number": 4}})
        assert answer.status_code == 200 and answer.json()["mean_fraction"] > 0


def test_a_local_non_browser_client_needs_no_xsrf():
    with client() as c:
        assert c.post("/api/design", json={"set": {"lens.f_number": 4}}).status_code == 200


def test_a_token_in_the_url_becomes_a_cookie_and_leaves_the_address_bar():
    with client(Access(token=TOKEN)) as c:
        first = c.get(f"/?token={TOKEN}&lens.f_number=4", follow_redirects=False)
        assert first.status_code == 303 and first.headers["location"] == "/?lens.f_number=4"
        assert "HttpOnly" in first.headers["set-cookie"] and "SameSite=Strict" in first.headers["set-cookie"]
        assert c.get("/").status_code == 200
        assert browser_post(c, "/api/design", {}).status_code == 200


def test_a_token_by_header_serves_a_script():
    with client(Access(token=TOKEN)) as c:
        answer = c.post("/api/design", json={}, headers={"Authorization": f"token {TOKEN}"})
        assert answer.status_code == 200


def test_every_answer_carries_the_security_headers_and_no_cors():
    with client() as c:
        for answer in (
            c.get("/"),
            c.get("/api/config"),
            c.post("/api/design", json={"set": {"x.y": 1}}),
            c.get("/", headers={"Host": "evil.example"}),
        ):
            assert answer.headers["x-content-type-options"] == "nosniff"
            assert "script-src 'self'" in answer.headers["content-security-policy"]
            assert "frame-ancestors 'none'" in answer.headers["content-security-policy"]
            assert not any(h.startswith("access-control-") for h in answer.headers)


# ---- foreign hosts (DNS rebinding) ---------------------------------------------------------------------------


@pytest.mark.parametrize(
    "host",
    ["evil.example", "evil.example:8050", "127.0.0.1.evil.example", "localhost.evil", "", "[::2]:8050", "0.0.0.0"],
)
@pytest.mark.parametrize("method, path", [("GET", "/"), ("GET", "/api/config"), ("POST", "/api/design")])
def test_a_foreign_host_is_refused(host, method, path):
    with client() as c:
        answer = c.request(method, path, headers={"Host": host}, json={} if method == "POST" else None)
        assert answer.status_code == 403 and "host not allowed" in answer.json()["error"]


def test_allowed_hosts_are_the_loopback_and_the_ones_given():
    access = Access.for_server("127.0.0.1", ["lab-pc.local"])
    with client(access) as c:
        for host in ("localhost:8050", "127.0.0.1", "[::1]:8050", "LAB-PC.local:8050"):
            assert c.get("/api/config", headers={"Host": host}).status_code == 200, host


def test_a_server_beyond_the_loopback_always_has_a_token():
    access = Access.for_server("0.0.0.0")
    assert access.token is not None and len(access.token) >= 24
    assert Access.for_server("127.0.0.1").token is None
    assert Access.for_server("::1").token is None


# ---- cross-origin and forged state-changing requests ---------------------------------------------------------


@pytest.mark.parametrize(
    "content_type, data",
    [
        ("text/plain", json.dumps({"path": "/tmp/x.toml"})),
        ("application/x-www-form-urlencoded", "path=%2Ftmp%2Fx.toml"),
        (
            "multipart/form-data; boundary=b",
            '--b\r\nContent-Disposition: form-data; name="path"\r\n\r\n/tmp/x\r\n--b--\r\n',
        ),
    ],
)
@pytest.mark.parametrize("origin", ["http://evil.example", None])
def test_simple_requests_never_act(content_type, data, origin):
    headers = {"Content-Type": content_type, **({"Origin": origin} if origin else {})}
    with client() as c:
        for path in ("/api/profile", "/api/design", "/api/load"):
            answer = c.post(path, content=data, headers=headers)
            assert answer.status_code in (403, 415), (path, answer.status_code)


@pytest.mark.parametrize("origin", ["http://evil.example", "null", "http://127.0.0.1:9999", "https://127.0.0.1:8050"])
def test_a_json_post_from_another_origin_is_refused(origin):
    with client() as c:
        c.get("/")
        answer = c.post(
            "/api/profile",
            json={"path": str(EXAMPLE)},
            headers={"Origin": origin, "X-XSRF-Token": c.cookies.get("_xsrf", "")},
        )
        assert answer.status_code == 403 and "cross-origin" in answer.json()["error"]


@pytest.mark.parametrize("xsrf", [None, "", "forged"])
def test_a_browser_post_without_the_xsrf_token_is_refused(xsrf):
    with client() as c:
        c.get("/")
        headers = {"Origin": LOCAL, **({"X-XSRF-Token": xsrf} if xsrf is not None else {})}
        answer = c.post("/api/design", json={}, headers=headers)
        assert answer.status_code == 403 and "XSRF" in answer.json()["error"]


def test_a_preflight_gets_no_cors_permission():
    with client() as c:
        answer = c.options(
            "/api/design", headers={"Origin": "http://evil.example", "Access-Control-Request-Method": "POST"}
        )
        assert answer.status_code >= 400 and "access-control-allow-origin" not in answer.headers


@pytest.mark.parametrize(
    "credentials",
    [
        {},
        {"params": {"token": "wrong-token"}},
        {"headers": {"Authorization": "token wrong-token"}},
        {"cookies": {"uwlab_token": "wrong-token"}},
        {"headers": {"Authorization": f"Bearer {TOKEN}"}},
    ],
)
def test_a_missing_or_forged_token_is_refused(credentials):
    cookies = credentials.pop("cookies", None)
    with client(Access(token=TOKEN)) as c:
        if cookies:
            c.cookies.update(cookies)
        for method, path in (("GET", "/"), ("GET", "/api/config"), ("POST", "/api/design")):
            answer = c.request(method, path, json={} if method == "POST" else None, **credentials)
            assert answer.status_code == 403 and "token" in answer.json()["error"]


# ---- files: only the explorer's roots, the same refusal whether a path exists or not -------------------------


@pytest.mark.parametrize("key", ["light.spectrum", "lens.transmittance", "target.reflectance", "water.type"])
def test_a_file_outside_the_roots_is_refused_without_its_content(key, secret_file):
    with client() as c:
        answer = c.post("/api/design", json={"set": {key: str(secret_file)}})
        assert answer.status_code == 422 and answer.json()["error"].endswith(OUTSIDE_ROOTS)
        assert "SECRET" not in answer.text and "hunter2" not in answer.text


def test_existing_and_missing_paths_get_the_same_refusal(secret_file):
    with client() as c:
        errors = [
            c.post("/api/design", json={"set": {"light.spectrum": str(p)}}).json()["error"]
            for p in (secret_file, secret_file.with_name("missing.csv"), "/etc/passwd", "/no/such/dir/x.csv")
        ]
    assert {e.split(": ", 1)[1] for e in errors} == {OUTSIDE_ROOTS}


@pytest.mark.parametrize(
    "value", ["../../../../../../etc/hostname", "~/.ssh/id_rsa.csv", "/dev/zero", "/proc/self/environ"]
)
def test_path_tricks_are_refused(value):
    with client() as c:
        answer = c.post("/api/design", json={"set": {"light.spectrum": value}})
        assert answer.status_code == 422 and answer.json()["error"].endswith(OUTSIDE_ROOTS)


def test_a_link_out_of_a_root_and_a_fifo_inside_one_are_refused(tmp_path, secret_file):
    served_dir = tmp_path / "served"
    served_dir.mkdir()
    config = served_dir / "design.toml"
    config.write_text(EXAMPLE.read_text())
    (served_dir / "link.csv").symlink_to(secret_file)
    os.mkfifo(served_dir / "fifo.csv")
    with client(served=load_served(config)) as c:
        for name in ("link.csv", "fifo.csv"):
            answer = c.post("/api/design", json={"set": {"light.spectrum": name}})
            assert answer.status_code == 422 and answer.json()["error"].endswith(OUTSIDE_ROOTS), name
            assert "SECRET" not in answer.text


def test_profiles_and_uploads_may_not_name_outside_files(secret_file, tmp_path):
    with client() as c:
        for path in (str(secret_file), "/etc/passwd", str(tmp_path / "nothing.toml")):
            answer = c.post("/api/profile", json={"path": path})
            assert answer.status_code == 422 and answer.json()["error"].endswith(OUTSIDE_ROOTS)
        answer = c.post("/api/load", json={"toml": f'[light]\nspectrum = "{secret_file}"\n'})
        assert answer.status_code == 422 and answer.json()["error"].endswith(OUTSIDE_ROOTS)
        assert "SECRET" not in answer.text


# ---- sizes and nesting ---------------------------------------------------------------------------------------


def test_an_oversized_body_is_refused_and_not_echoed():
    body = json.dumps({"set": {"light.spectrum": "A" * 2_000_000}})
    with client() as c:
        answer = c.post("/api/design", content=body, headers={"Content-Type": "application/json"})
    assert answer.status_code == 413 and len(answer.content) < 200


def test_a_streamed_body_is_cut_at_the_limit():
    def chunks():
        yield b'{"set": {"light.spectrum": "'
        for _ in range(30):
            yield b"A" * 100_000
        yield b'"}}'

    with client() as c:
        answer = c.post("/api/design", content=chunks(), headers={"Content-Type": "application/json"})
    assert answer.status_code == 413 and len(answer.content) < 200


@pytest.mark.parametrize("depth", [40, 100_000])
def test_deeply_nested_json_is_one_line_error(depth):
    body = "[" * depth + "]" * depth
    with client() as c:
        answer = c.post("/api/design", content=body, headers={"Content-Type": "application/json"})
    assert answer.status_code == 422 and "nested deeper" in answer.json()["error"]


def test_a_large_value_is_not_echoed_in_the_error():
    with client() as c:
        answer = c.post("/api/design", json={"set": {"lens.f_number": "x" * 500_000}})
    assert answer.status_code == 422 and len(answer.content) < 1000


# ---- one file boundary: every file-valued value, every endpoint, checked before anything is opened -----------


@pytest.fixture
def opened(monkeypatch):
    """The files the model reads (`uwlab.model.data.read_text`, under every CSV and TOML reader)."""
    paths: list[Path] = []
    real = data.read_text

    def recording(path, *args, **kwargs):
        paths.append(Path(path).resolve())
        return real(path, *args, **kwargs)

    monkeypatch.setattr(data, "read_text", recording)
    return paths


def test_no_file_outside_the_roots_is_opened_or_quoted_through_any_key_or_endpoint(tmp_path, opened):
    outside = plant_secrets(tmp_path / "outside")
    served_dir = tmp_path / "served"
    served_dir.mkdir()
    (served_dir / "design.toml").write_text(EXAMPLE.read_text())
    (served_dir / "led.csv").write_text("wavelength_nm,relative\n400,1\n700,1\n")
    probes = file_probes(outside)
    with client(served=load_served(served_dir / "design.toml")) as c:
        for name, path, body in probes:
            answer = c.post(path, json=body)
            assert answer.status_code == 422, (name, answer.status_code, answer.text[:200])
            assert answer.json()["error"].endswith(OUTSIDE_ROOTS), (name, answer.text[:200])
            assert SECRET_LINE not in answer.text, name
        assert c.post("/api/design", json={"set": {"light.spectrum": "led.csv"}}).status_code == 200
    assert len(probes) > 300
    assert (served_dir / "led.csv").resolve() in opened  # the recorder sees what the model reads
    assert not [p for p in opened if p.is_relative_to(outside.resolve())]


def test_a_sensor_profile_without_toml_or_with_a_trailing_separator_names_the_file_the_model_would_open(tmp_path):
    outside = plant_secrets(tmp_path / "outside")
    with client() as c:
        for value in (str(outside / "secret"), f"{outside}/secret.toml/", f"{outside}/secret.toml/."):
            answer = c.post("/api/design", json={"set": {"sensor.profile": value}})
            assert answer.status_code == 422 and answer.json()["error"].endswith(OUTSIDE_ROOTS), value
        # inside the roots, the same forms reach the profile they name (a name, a path, a path with "/.")
        profile = CONFIGS / "sensors" / "imx250m.toml"
        for value in ("IMX250M", str(profile), f"{profile}/."):
            answer = c.post("/api/design", json={"set": {"sensor.profile": value}})
            assert answer.status_code == 200, (value, answer.text[:200])


def test_a_sweep_over_files_checks_every_value(tmp_path, secret_file):
    inside = CONFIGS / "sensors" / "imx250m.toml"
    with client() as c:
        allowed = c.post("/api/sweep", json={"grid": {"sensor.profile": ["imx250m", str(inside)]}, "output": "snr_db"})
        assert allowed.status_code == 200 and allowed.json()["values"][0] == allowed.json()["values"][1]
        refused = c.post("/api/sweep", json={"grid": {"water.type": f"jerlov-I,{secret_file}"}, "output": "snr_db"})
        assert refused.status_code == 422 and refused.json()["error"].endswith(OUTSIDE_ROOTS)
        assert "SECRET" not in refused.text


def test_a_link_out_of_a_root_is_refused_in_a_grid_and_as_a_profile(tmp_path):
    outside = plant_secrets(tmp_path / "outside")
    served_dir = tmp_path / "served"
    served_dir.mkdir()
    config = served_dir / "design.toml"
    config.write_text(EXAMPLE.read_text())
    (served_dir / "water.csv").symlink_to(outside / "secret.csv")
    (served_dir / "sensor.toml").symlink_to(outside / "secret.toml")
    with client(served=load_served(config)) as c:
        for body in (
            {"grid": {"water.type": ["water.csv"]}, "output": "snr_db"},
            {"grid": {"sensor.profile": ["sensor.toml/."]}, "output": "snr_db"},
        ):
            answer = c.post("/api/sweep", json=body)
            assert answer.status_code == 422 and answer.json()["error"].endswith(OUTSIDE_ROOTS), body
            assert SECRET_LINE not in answer.text
        answer = c.post("/api/profile", json={"path": "sensor.toml"})
        assert answer.status_code == 422 and answer.json()["error"].endswith(OUTSIDE_ROOTS)


@pytest.mark.parametrize(
    "body",
    [
        {"toml": "x = 1", "name": "n" * 300},
        {"toml": '[lens]\ntransmittance = "' + "t" * 5000 + '.csv"'},
        {"toml": '[sensor]\nprofile = "' + "p" * 300 + '"'},
        {"toml": '[lens]\nname = "' + "n" * 100_000 + '"'},
    ],
)
def test_long_names_in_an_upload_are_one_line_errors(body):
    with client() as c:
        answer = c.post("/api/load", json=body)
    assert answer.status_code == 422 and len(answer.content) < 2000


# ---- the guard as an ASGI wrapper: Host, redirects, cookies, a body cut short --------------------------------


async def _ok(scope, receive, send):
    """A stand-in application: reads the body, answers 200 (the guard assumes nothing of what it guards)."""
    while (await receive()).get("more_body"):
        pass
    await send({"type": "http.response.start", "status": 200, "headers": []})
    await send({"type": "http.response.body", "body": b"ok"})


def call(
    guard: Guard,
    path: str = "/",
    query: bytes = b"",
    host: bytes = b"127.0.0.1:8050",
    method: str = "GET",
    body: list[dict] | None = None,
    headers: list | None = None,
) -> list[dict]:
    """The messages ``guard`` sends for one request (raw_path as a server gives it, percent-encoded)."""
    raw = quote(path, safe="/\\%").encode()
    scope = {
        "type": "http",
        "method": method,
        "path": path,
        "raw_path": raw,
        "query_string": query,
        "headers": [(b"host", host), *(headers or [])],
        "scheme": "http",
    }
    incoming = list(body or [{"type": "http.request", "body": b"", "more_body": False}])
    sent: list[dict] = []

    async def receive():
        return incoming.pop(0) if incoming else {"type": "http.disconnect"}

    async def send(message):
        sent.append(message)

    asyncio.run(guard(scope, receive, send))
    return sent


def start(sent: list[dict]) -> tuple[int, dict[bytes, bytes]]:
    first = sent[0]
    return first["status"], dict(first["headers"])


@pytest.mark.parametrize(
    "host",
    [
        b"127.0.0.1:8050.evil.com",
        b"localhost:8050@evil.com",
        b"[localhost]:8050",
        b"localhost:",
        b"::1",
        b"127.0.0.1:80:80",
        b"[::1",
        b"[::1]x",
        b"localhost:123456",
        b"local host",
        b"\xe9vil",
        b"localhost/x",
    ],
)
def test_a_host_header_that_is_not_host_port_is_400(host):
    status, _ = start(call(Guard(_ok, Access()), host=host))
    assert status == 400


@pytest.mark.parametrize("host", [b"localhost", b"LOCALHOST:1", b"127.0.0.1:65535", b"[::1]", b"[0:0::1]:8050"])
def test_allowed_hosts_in_every_rfc_3986_form_are_served(host):
    assert start(call(Guard(_ok, Access()), host=host))[0] == 200


def test_two_host_headers_are_400():
    sent = call(Guard(_ok, Access()), headers=[(b"host", b"evil.example")])
    assert start(sent)[0] == 400


@pytest.mark.parametrize(
    "path",
    [
        "//evil.example/",
        "///evil.example/x",
        "/\\evil.example/",
        "/\\/evil.example",
        "/%2F%2Fevil.example/",
        "/\u20ac",
        "/a/../..//evil.example",
    ],
)
def test_the_token_redirect_stays_on_the_server(path):
    status, headers = start(call(Guard(_ok, Access(token=TOKEN)), path, f"token={TOKEN}&x=1".encode()))
    location = headers[b"location"].decode()
    assert status == 303 and location.startswith("/") and location[1:2] not in ("/", "\\")
    assert not urlsplit(location).netloc and not urlsplit(location).scheme and "\\" not in location
    assert location.endswith("?x=1")


def test_only_the_servers_own_token_is_written_into_a_cookie():
    guard = Guard(_ok, Access(token=TOKEN))
    status, headers = start(call(guard, query=f"token={TOKEN}".encode()))
    assert status == 303 and headers[b"set-cookie"].startswith(f"uwlab_token={TOKEN}; ".encode())
    # a wrong token beside a right cookie: redirected, and no cookie is written from it
    forged = b"token=abcdefgh%3B%20Domain%3Devil.example"
    status, headers = start(call(guard, query=forged, headers=[(b"cookie", f"uwlab_token={TOKEN}".encode())]))
    assert status == 303 and b"set-cookie" not in headers
    assert start(call(guard, query=forged))[0] == 403


@pytest.mark.parametrize("token", ["short", "a;b=cdefgh", "abc defgh", "abcdefgh\u20ac", "x" * 257])
def test_a_token_outside_the_token_characters_is_refused(token):
    with pytest.raises(ValueError):
        Access(token=token)


def test_a_body_cut_short_ends_the_request_quietly():
    parts = [{"type": "http.request", "body": b'{"a": ', "more_body": True}]
    sent = call(Guard(_ok, Access()), method="POST", body=parts, headers=[(b"content-type", b"application/json")])
    assert sent == []
