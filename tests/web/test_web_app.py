"""``rig serve`` on the loopback, over HTTP: the clinician's pages and the JSON API (patients,
search, the pseudonym check, sessions, the report rendered once into the server's cache and
served inline, progress, downloads), and the bad input each refused with one clear line and
nothing written (the store's rows and the server's files compared before and after).
"""

from __future__ import annotations

import os
import re
import stat
from types import SimpleNamespace

import pytest

from tests.web.clinic import CONSTRAINT, client, clinic_store, running, snapshot

pytestmark = pytest.mark.xdist_group("web_app")


@pytest.fixture(scope="module")
def web(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("web")
    ids = clinic_store(tmp / "clinic.db")
    cache = tmp / "cache"
    with running(["--db", str(tmp / "clinic.db"), "--cache", str(cache)], tmp) as server:
        c = client(server)
        try:
            yield SimpleNamespace(server=server, c=c, ids=ids, tmp=tmp, cache=cache)
        finally:
            c.close()


def test_patients_search_and_create(web):
    c = web.c
    page = c.get("/patients").text
    assert "P-0042" in page and "P-0043" in page
    found = c.post("/patients/search", data={"csrftoken": c.cookies["csrftoken"], "q": "0043"})
    assert found.status_code == 200
    assert ">P-0043</a>" in found.text and ">P-0042</a>" not in found.text
    r = c.post("/patients", data={"csrftoken": c.cookies["csrftoken"], "pseudonym": "P-0100",
                                  "side": "left"})
    assert r.status_code == 303
    new = re.fullmatch(r"/patients/(\d+)", r.headers["location"])
    assert new and "P-0100" in c.get(r.headers["location"]).text
    # the CLI's pseudonym warning: asked first, created when confirmed, the warning kept
    r = c.post("/api/patients", json={"pseudonym": "Anna Weber", "confirm": True})
    assert r.status_code == 201 and "a person's name" in r.json()["warning"]
    api = c.post("/api/patients/search", json={"q": "anna"}).json()["patients"]
    assert [p["pseudonym"] for p in api] == ["Anna Weber"]


def test_session_report_progress_and_files(web):
    c, ids, cache = web.c, web.ids, web.cache
    p42, (s1, s2) = ids["p42"], ids["p42_visits"]
    page = c.get(f"/patients/{p42}/sessions/{s2}")
    assert page.status_code == 200 and "Open the report" in page.text
    r1 = c.get(f"/patients/{p42}/sessions/{s2}/report")
    assert r1.status_code == 200 and r1.headers["content-type"].startswith("text/html")
    assert "script-src" not in r1.headers["content-security-policy"]  # no script at all
    assert "Progress across visits" in r1.text  # the second visit: the report's section
    r2 = c.get(f"/patients/{p42}/sessions/{s2}/report")
    assert r2.text == r1.text
    reports = list((cache / "reports").iterdir())
    assert len(reports) == 1  # rendered once, then served from the cache
    assert stat.S_IMODE(reports[0].stat().st_mode) == 0o600
    assert stat.S_IMODE((cache / "reports").stat().st_mode) == 0o700
    prog = c.get(f"/patients/{p42}/progress")
    assert prog.status_code == 200 and "data:image/png;base64" in prog.text
    js = c.get(f"/api/patients/{p42}/progress").json()
    assert [v["session"] for v in js["visits"]] == [s1, s2]
    # the files of a session; the names the browser saves carry no pseudonym
    p43, s3 = ids["p43"], ids["p43_session"]
    offered = c.get(f"/api/patients/{p43}/sessions/{s3}").json()["downloads"]
    assert sorted(offered) == ["constraint", "export", "limb", "model"]
    con = c.get(offered["constraint"])
    assert con.text == CONSTRAINT
    assert con.headers["content-disposition"] == (
        f'attachment; filename="session-{s3}-constraint.yaml"')
    assert c.get(offered["model"]).content == ids["model"].read_bytes()
    sto = c.get(offered["export"])
    assert sto.status_code == 200 and "endheader" in sto.text
    assert list((cache / "exports").iterdir()) == []  # the export's file went once sent


def test_headers_and_log_hold_no_pseudonym(web):
    server, c, ids = web.server, web.c, web.ids
    r = c.get("/patients")
    h = r.headers
    assert "'unsafe-inline'" not in h["content-security-policy"]
    assert "frame-ancestors 'none'" in h["content-security-policy"]
    assert h["x-content-type-options"] == "nosniff" and h["referrer-policy"] == "no-referrer"
    c.get(f"/patients/{ids['p42']}/progress?joint=elbow")
    log = server.log()
    assert "GET /patients" in log and "P-00" not in log and "Anna" not in log
    assert f"GET /patients/{ids['p42']}/progress HTTP" in log and "joint=" not in log


def _multipart(c, fields: list[tuple[str, object]]):
    """A multipart body in the order given (the CSRF token first, as the page's form)."""
    return c.build_request("POST", "/", files=fields)


BAD_API = [
    # (method, path, json / content, status, words in the one-line error)
    ("POST", "/api/patients", None, 422, "the body is missing"),
    ("POST", "/api/patients", {}, 422, "pseudonym: is missing"),
    ("POST", "/api/patients", {"pseudonym": 42}, 422, "pseudonym: must be text"),
    ("POST", "/api/patients", {"pseudonym": "  "}, 400, "give the patient's pseudonym"),
    ("POST", "/api/patients", {"pseudonym": "P-1", "side": "middle"}, 422,
     "side: must be 'left' or 'right'"),
    ("POST", "/api/patients", {"pseudonym": "P-1", "age": 40}, 422,
     "age: is not a field of this request"),
    ("POST", "/api/patients", {"pseudonym": "P-0042"}, 400, "already exists"),
    ("POST", "/api/patients", {"pseudonym": "P-0042 1961-04-12"}, 409, "a date"),
    ("POST", "/api/patients", "{not json", 400, "the body is not valid JSON"),
    ("POST", "/api/patients", {"pseudonym": "P" * 65}, 422, "pseudonym: is too long"),
    ("POST", "/api/patients", {"pseudonym": "P-1", "confirm": "yes"}, 422,
     "confirm: must be true or false"),
    ("POST", "/api/patients", ["P-1"], 422, "the body must be a JSON object"),
    ("POST", "/api/patients/search", {"q": 5}, 422, "q: must be text"),
    ("GET", "/api/patients/abc", None, 404, "patient_id: must be a whole number, got 'abc'"),
    ("GET", "/api/patients/999", None, 404, "no patient 999"),
    ("GET", "/api/patients/{p42}/sessions/{s3}", None, 404, "has no session"),
    ("GET", "/api/patients/{p42}/progress?joint=elbw", None, 400, "elbw"),
    ("GET", "/api/patients/{p43}/progress?joint=knee", None, 400, "no session of the knee"),
    ("GET", "/api/nowhere", None, 404, "no page /api/nowhere"),
]


@pytest.mark.parametrize("method, path, body, status, words", BAD_API,
                         ids=[f"{i}-{c[1]}" for i, c in enumerate(BAD_API)])
def test_bad_api_input(web, method, path, body, status, words):
    c, ids, tmp, cache = web.c, web.ids, web.tmp, web.cache
    path = path.format(p42=ids["p42"], p43=ids["p43"], s3=ids["p43_session"])
    before = snapshot(tmp, cache)
    kw = {"content": body} if isinstance(body, str) else (
        {} if body is None else {"json": body})
    if isinstance(body, str):
        kw["headers"] = {"content-type": "application/json"}
    r = c.request(method, path, **kw)
    assert r.status_code == status, r.text
    assert words in r.json()["error"] and "\n" not in r.json()["error"]
    assert snapshot(tmp, cache) == before


def _bad_forms(ids, token):
    p42, p43 = ids["p42"], ids["p43"]
    s1, s3 = ids["p42_visits"][0], ids["p43_session"]
    report = f"/patients/{p42}/sessions/{s1}/report"
    tok = ("csrftoken", (None, token))
    big = b"x: " + b"0" * (2 << 20)
    return [
        # (name, method, path, request kwargs, status, words)
        ("form without CSRF token", "POST", "/patients", {"data": {"pseudonym": "P-9"}}, 403,
         "missing or wrong CSRF token"),
        ("form with a wrong CSRF token", "POST", "/patients",
         {"data": {"csrftoken": token[:-2] + "xx", "pseudonym": "P-9"}}, 403, "CSRF"),
        ("API call without the header", "POST", "/api/patients",
         {"json": {"pseudonym": "P-9"}, "headers": {"x-csrftoken": ""}}, 403, "CSRF"),
        ("a form from another site", "POST", "/patients",
         {"data": {"csrftoken": token, "pseudonym": "P-9"},
          "headers": {"origin": "http://evil.example"}}, 403, "another site"),
        ("missing pseudonym", "POST", "/patients", {"data": {"csrftoken": token}}, 400,
         "give the patient's pseudonym"),
        ("a side that is neither", "POST", "/patients",
         {"data": {"csrftoken": token, "pseudonym": "P-9", "side": "middle"}}, 400,
         "side must be one of left, right; got 'middle'"),
        ("an unknown joint's progress", "GET", f"/patients/{p42}/progress?joint=neck", {},
         400, "neck"),
        ("a name as pseudonym, not confirmed", "POST", "/patients",
         {"data": {"csrftoken": token, "pseudonym": "Jane Doe"}}, 409, "a person's name"),
        ("age not a number", "POST", report, {"files": [tok, ("age", (None, "forty"))]}, 400,
         "age must be a whole number, got 'forty'"),
        ("age out of range", "POST", report, {"files": [tok, ("age", (None, "5"))]}, 400,
         "from 18 to 110"),
        ("unknown sex", "POST", report, {"files": [tok, ("sex", (None, "other"))]}, 400,
         "sex must be female or male"),
        ("path trick in a file name", "POST", report,
         {"files": [tok, ("reference", ("../../etc/evil.yaml", b"a: 1\n"))]}, 400,
         "plain file name"),
        ("wrong kind of file", "POST", report,
         {"files": [tok, ("reference", ("model.exe", b"MZ"))]}, 400, ".yaml) is expected"),
        ("not a constraint", "POST", report,
         {"files": [tok, ("reference", ("ref.yaml", b"hello: [1\n"))]}, 400, "ref.yaml"),
        ("oversized upload", "POST", report,
         {"files": [tok, ("reference", ("ref.yaml", big))]}, 413, "larger than the 1024 KiB"),
        ("oversized upload, no length given", "POST", "/patients",
         {"content": iter([b"csrftoken=" + token.encode(), b"&pseudonym=" + b"P" * (2 << 20)]),
          "headers": {"content-type": "application/x-www-form-urlencoded"}}, 413, "larger"),
        ("a file before the CSRF token", "POST", report,
         {"files": [("reference", ("ref.yaml", b"a: 1\n")), tok]}, 403, "before any file"),
        ("another patient's session: report", "GET",
         f"/patients/{p42}/sessions/{s3}/report", {}, 404, f"patient {p42} has no session"),
        ("another patient's session: file", "GET",
         f"/patients/{p42}/sessions/{s3}/files/constraint", {}, 404, "has no session"),
        ("path trick in a download", "GET",
         f"/patients/{p43}/sessions/{s3}/files/..%2F..%2Fclinic.db", {}, 404, ""),
        ("a file the session lacks", "GET", f"/patients/{p42}/sessions/{s1}/files/model", {},
         404, "no trained model"),
        ("an id that is not a number", "GET", "/patients/P-0042", {}, 404,
         "must be a whole number"),
        ("a method the page lacks", "DELETE", f"/patients/{p42}",
         {"headers": {"x-csrftoken": token}}, 405, "DELETE is not allowed"),
    ]


def test_bad_form_input(web):
    """Each refused with its one line on the error page (or the form again), nothing
    written."""
    c, ids, tmp, cache = web.c, web.ids, web.tmp, web.cache
    for name, method, path, kw, status, words in _bad_forms(ids, c.cookies["csrftoken"]):
        before = snapshot(tmp, cache)
        headers = {"x-csrftoken": "", **kw.pop("headers", {})}
        r = c.request(method, path, headers=headers, **kw)
        assert r.status_code == status, (name, r.status_code, r.text[-400:])
        assert "Traceback" not in r.text, name
        if words and r.headers["content-type"].startswith("application/json"):
            assert words in r.json()["error"], name
        elif words:
            msg = re.search(r'id="error-message">([^<]*)<', r.text) or re.search(
                r'id="pseudonym-warning">\s*<p>([^<]*)<', r.text)
            assert msg and words in msg.group(1).replace("&#39;", "'"), (name, r.text[-600:])
        assert snapshot(tmp, cache) == before, name


def test_in_the_browser(web):
    """Chromium: a patient created past the pseudonym warning, a patient and a session, and
    mistakes shown as one line on the error page; no page's own Content-Security-Policy
    refuses what it needs. With RIG_WEB_SHOTS=DIR each page, and the report and the progress
    page too, is saved there as a PNG (docs/web/ holds them)."""
    from selenium.webdriver.common.by import By

    from tests.web.browser import quit_chromium, require_driver, start_chromium

    require_driver()
    shots = os.environ.get("RIG_WEB_SHOTS")
    b = start_chromium(height=900)

    def shot(name: str) -> None:
        if shots:
            b.save_screenshot(os.path.join(shots, f"{name}.png"))

    try:
        ids = web.ids
        b.get(web.server.url + "/patients")
        assert b.find_element(By.ID, "patients").text.count("P-004") == 2
        shot("patients")
        b.find_element(By.ID, "pseudonym").send_keys("Maria Lopez")
        click_and_wait(b, b.find_element(By.ID, "create"))
        warning = b.find_element(By.ID, "pseudonym-warning").text
        assert "a person's name" in warning
        shot("pseudonym-warning")
        click_and_wait(b, b.find_element(By.ID, "confirm-create"))
        assert b.find_element(By.ID, "patient-pseudonym").text == "Maria Lopez"
        assert "/patients/" in b.current_url and "Maria" not in b.current_url
        p42, (s1, s2) = ids["p42"], ids["p42_visits"]
        b.get(f"{web.server.url}/patients/{p42}")
        shot("patient")
        click_and_wait(b, b.find_element(By.LINK_TEXT, str(s2)))
        shot("session")
        if shots:  # the report and progress pages' HTML is checked over HTTP above
            click_and_wait(b, b.find_element(By.ID, "report-link"))
            assert "Progress across visits" in b.page_source
            shot("report")
            b.get(f"{web.server.url}/patients/{p42}/progress")
            assert "Progress across visits" in b.find_element(By.ID, "progress").text
            shot("progress")
        # mistakes: one line on the error page, no traceback
        b.get(f"{web.server.url}/patients/{p42}/sessions/{ids['p43_session']}")
        assert b.find_element(By.ID, "error-message").text == (
            f"patient {p42} has no session {ids['p43_session']}")
        shot("error-other-patients-session")
        b.get(f"{web.server.url}/patients/{p42}/sessions/{s1}")
        b.find_element(By.ID, "age").send_keys("forty")
        click_and_wait(b, b.find_element(By.CSS_SELECTOR, "#report-options button"))
        assert b.find_element(By.ID, "error-message").text == (
            "age must be a whole number, got 'forty'")
        shot("error-age")
        assert "Traceback" not in b.page_source
        errors = [e for e in b.get_log("browser") if e["level"] == "SEVERE"
                  and "Content Security Policy" in e["message"]]
        assert errors == []  # nothing the page needs is refused by its own policy
    finally:
        quit_chromium(b)


def click_and_wait(browser, element, timeout: float = 60.0) -> None:
    """Click ``element`` and wait until the page it was on is gone (the next one loads)."""
    from selenium.webdriver.support import expected_conditions as ec
    from selenium.webdriver.support.ui import WebDriverWait

    page = browser.find_element("tag name", "html")
    element.click()
    WebDriverWait(browser, timeout).until(ec.staleness_of(page))
