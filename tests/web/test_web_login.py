"""``rig serve`` beyond the loopback: refused without a user, then every page and API call needs
a login (Argon2-hashed users in an owner-only file); unauthenticated requests are refused with
one line and nothing written; the login form itself is CSRF-protected and sends nowhere but
this site.
"""

from __future__ import annotations

import contextlib
import socket
import stat
from types import SimpleNamespace

import httpx
import pytest
from argon2 import PasswordHasher
from click.testing import CliRunner

from rig.commands.serve import serve
from rig.errors import RigConfigError
from rig.web.security import (
    LOGIN_FAILURES_PER_ADDRESS,
    LOGIN_FAILURES_PER_USER,
    LOGIN_WINDOW_S,
    LoginThrottle,
    UserFile,
)
from tests.web.clinic import clinic_store, running, snapshot

pytestmark = pytest.mark.xdist_group("web_login")
PASSWORD = "correct horse battery"
# Argon2id at its smallest cost for the tests' users (the server checks a stored hash with the
# parameters written in it); the product's default is argon2-cffi's (RFC 9106, 64 MiB, t=3)
CHEAP = PasswordHasher(time_cost=1, memory_cost=8, parallelism=1)


def test_users_file(tmp_path):
    users = UserFile(tmp_path / "u.json", CHEAP)
    users.add("clin.1", PASSWORD)
    assert stat.S_IMODE((tmp_path / "u.json").stat().st_mode) == 0o600
    assert "argon2id" in (tmp_path / "u.json").read_text()
    assert PASSWORD not in (tmp_path / "u.json").read_text()
    assert users.verify("clin.1", PASSWORD)
    assert not users.verify("clin.1", PASSWORD + "x") and not users.verify("nobody", PASSWORD)
    with pytest.raises(RigConfigError, match="at least 8 characters"):
        users.add("clin.2", "short")
    with pytest.raises(RigConfigError, match=r"user name '\.\./x'"):
        users.add("../x", PASSWORD)


def test_add_user_command_and_refusal_without_users(tmp_path, rig_cli):
    db = tmp_path / "c.db"
    code, _, err = rig_cli(["serve", "--db", db, "--host", "0.0.0.0", "--port", "0"])
    assert code == 2 and "needs a login and there is no user yet" in err
    assert len(err.strip().splitlines()) == 1 and not db.exists()
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen(1)
        port = taken.getsockname()[1]
        for args, words in ((["--port", "70000"], "--port must be 0-65535, got 70000"),
                            (["--port", "0", "--login"], "needs a login and there is no user"),
                            (["--port", str(port)], f"--port {port}: cannot listen there")):
            code, _, err = rig_cli(["serve", "--db", db, *args])
            assert code == 2 and words in err and len(err.strip().splitlines()) == 1, err
    assert not db.exists()
    r = CliRunner().invoke(serve, ["--db", str(db), "--add-user", "clin.1"],
                           input=f"{PASSWORD}\n{PASSWORD}\n")
    assert r.exit_code == 0, r.output
    assert UserFile(str(db) + ".users.json").verify("clin.1", PASSWORD)
    assert "$argon2id$v=19$m=65536,t=3,p=4$" in (tmp_path / "c.db.users.json").read_text()


@pytest.fixture(scope="module")
def remote(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("web-login")
    ids = clinic_store(tmp / "clinic.db")
    db = tmp / "clinic.db"
    users = tmp / "users.json"
    UserFile(users, CHEAP).add("clin.1", PASSWORD)
    cache = tmp / "cache-login"
    with running(["--db", str(db), "--host", "0.0.0.0", "--users", str(users), "--cache",
                  str(cache), "--no-access-log"], tmp) as server:
        port = server.url.rsplit(":", 1)[1]
        yield SimpleNamespace(url=f"http://127.0.0.1:{port}", ids=ids, tmp=tmp, cache=cache)


@contextlib.contextmanager
def _client(url: str):
    with httpx.Client(base_url=url, timeout=60.0) as c:
        c.get("/login")
        yield c


def test_unauthenticated_requests_are_refused(remote):
    url, ids, tmp, cache = remote.url, remote.ids, remote.tmp, remote.cache
    p42, s1 = ids["p42"], ids["p42_visits"][0]
    with _client(url) as c:
        token = c.cookies["csrftoken"]
        cases = [
            ("GET", "/patients", {}, 303, None),
            ("GET", f"/patients/{p42}/sessions/{s1}/report", {}, 303, None),
            ("GET", f"/patients/{p42}/sessions/{s1}/files/export", {}, 303, None),
            ("GET", "/api/patients", {}, 401, "log in first"),
            ("GET", f"/api/patients/{p42}/progress", {}, 401, "log in first"),
            ("POST", "/api/patients", {"json": {"pseudonym": "P-7"},
                                       "headers": {"x-csrftoken": token}}, 401, "log in first"),
            ("POST", "/patients", {"data": {"csrftoken": token, "pseudonym": "P-7"}}, 401,
             "log in first"),
            ("POST", "/login", {"data": {"csrftoken": token, "username": "clin.1",
                                         "password": "wrong password"}}, 401,
             "wrong user name or password"),
            ("POST", "/login", {"data": {"csrftoken": token, "username": "nobody",
                                         "password": PASSWORD}}, 401,
             "wrong user name or password"),
            ("POST", "/login", {"data": {"username": "clin.1", "password": PASSWORD}}, 403,
             "CSRF"),
        ]
        for method, path, kw, status, words in cases:
            before = snapshot(tmp, cache)
            r = c.request(method, path, **kw)
            assert r.status_code == status, (method, path, r.text[-300:])
            if status == 303:
                assert r.headers["location"].startswith("/login?next=/patients")
            if words:
                assert words in r.text.replace("&#39;", "'"), (method, path)
            assert "P-0042" not in r.text and "rig_session" not in c.cookies
            assert snapshot(tmp, cache) == before, (method, path)
        # a login cookie signed by another server is nobody's
        c.cookies.set("rig_session", "eyJ1c2VyIjogImNsaW4uMSJ9.Zz.forged")
        assert c.get("/patients").status_code == 303
        assert c.get("/static/rig.css").status_code == 200  # the login page's own style


def test_login_then_pages_then_logout(remote):
    url = remote.url
    with _client(url) as c:
        token = c.cookies["csrftoken"]
        r = c.post("/login", data={"csrftoken": token, "username": "clin.1",
                                   "password": PASSWORD, "next": "//evil.example/x"})
        assert r.status_code == 303 and r.headers["location"] == "/"  # this site only
        cookie = r.headers["set-cookie"].lower()
        assert "httponly" in cookie and "samesite=lax" in cookie
        page = c.get("/patients")
        assert page.status_code == 200 and ">P-0042</a>" in page.text and "clin.1" in page.text
        assert c.get("/api/patients").status_code == 200
        assert c.post("/logout", data={"csrftoken": token}).status_code == 303
        assert c.get("/api/patients").status_code == 401



def test_failed_logins_are_throttled_per_user_and_per_address():
    """A sliding window on a test clock: the 6th failure of one user name waits, another user
    from the same address does not until the address's own limit, and both clear with time."""
    now = [1000.0]
    t = LoginThrottle(clock=lambda: now[0])
    for _ in range(LOGIN_FAILURES_PER_USER):
        assert t.wait_s("10.0.0.9", "clin.1") == 0
        t.failed("10.0.0.9", "clin.1")
        now[0] += 1.0
    assert t.wait_s("10.0.0.9", "clin.1") == pytest.approx(LOGIN_WINDOW_S - 5.0)
    assert t.wait_s("10.0.0.7", "clin.1") > 0  # the user name, from anywhere
    assert t.wait_s("10.0.0.9", "clin.2") == 0  # another user from that address
    for _ in range(LOGIN_FAILURES_PER_ADDRESS - LOGIN_FAILURES_PER_USER):
        t.failed("10.0.0.9", f"u{_}")
    assert t.wait_s("10.0.0.9", "clin.2") > 0  # the address's own limit
    assert t.wait_s("10.0.0.8", "clin.2") == 0
    now[0] += LOGIN_WINDOW_S
    assert t.wait_s("10.0.0.9", "clin.1") == 0 and t.wait_s("10.0.0.9", "clin.2") == 0
    t.failed("10.0.0.9", "clin.1")
    t.succeeded("clin.1")
    assert t._failed.get(("user", "clin.1")) is None


def test_the_server_refuses_a_sixth_guess_and_writes_nothing(remote):
    with _client(remote.url) as c:
        token = c.cookies["csrftoken"]
        guess = {"csrftoken": token, "username": "guesser", "password": "not the password"}
        before = snapshot(remote.tmp, remote.cache)
        for _ in range(LOGIN_FAILURES_PER_USER):
            assert c.post("/login", data=guess).status_code == 401
        r = c.post("/login", data=guess)
        assert r.status_code == 429 and "too many failed logins: try again in 15 min" in r.text
        assert snapshot(remote.tmp, remote.cache) == before
        r = c.post("/login", data={"csrftoken": token, "username": "clin.1",
                                   "password": PASSWORD})
        assert r.status_code == 303  # another user from the same address logs in
