"""Hostile requests against the explorer (uwlab/explore/security.py, inputs.check_files): none may succeed.

Each request is one a web page the user visits, a DNS-rebinding attacker or a curious client could send; the
assertions check that it is refused, that the refusal says nothing about the machine's files and repeats nothing of
the request, and that the user's own page still works.
"""

from __future__ import annotations

import json
import os

import pytest
from starlette.testclient import TestClient

from tests.support.paths import EXAMPLE
from uwlab.explore.app import create_app
from uwlab.explore.catalog import Catalog
from uwlab.explore.inputs import OUTSIDE_ROOTS, load_served
from uwlab.explore.security import Access

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
