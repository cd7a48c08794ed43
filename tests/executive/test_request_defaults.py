"""Request fields with a ``default``: optional in every request (run --request, a run with
no --request, the served API, the console's form data), type-checked at load with a
located error; trees/press_buttons.yaml takes its buttons this way."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from mmexec.config.yamlload import InputError
from mmexec.executive.campaign import CampaignOptions, RequestPlan, run_campaign
from mmexec.executive.campaign.requests import parse_draws, split_values
from mmexec.executive.cli import _cli_requests
from mmexec.executive.compiler import load_mission
from mmexec.executive.config import load_skill_modules
from mmexec.executive.eventlog import read_log
from mmexec.executive.runner import Progress, Request, Runner, RunOptions
from mmexec.executive.serve.app import create_app
from mmexec.executive.serve.console import mission_json
from mmexec.executive.serve.service import Service, ServiceError
from mmexec.skills.base import REGISTRY

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True, scope="module")
def _builtin_skills() -> None:
    load_skill_modules(None)  # the built-in skills (report, press_buttons, ...), as a run loads them

MISSION = """\
mission: counted
requests:
  who: {type: str}
  times: {type: int, default: 2, doc: "how often"}
  tags: {type: list, default: [a, b]}
tree:
  skill: report
  params: {message: "{request.who} x{request.times} {request.tags}"}
"""

ALL_DEFAULTS = """\
mission: greet
requests:
  times: {type: int, default: 2}
  tags: {type: list, default: []}
tree:
  skill: report
  params: {message: "times {request.times} tags {request.tags}"}
"""

CONFIG = """\
backend: mock
rate_hz: 20
"""


def write(tmp_path: Path, text: str, name: str = "m.yaml") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_default_used_when_left_out_and_a_given_value_overrides(tmp_path: Path) -> None:
    m = load_mission(write(tmp_path, MISSION))
    assert m.request_fields == {"who": str, "times": int, "tags": list}
    assert m.request_defaults == {"times": 2, "tags": ["a", "b"]}
    assert m.validate_request({"who": "ann"}) == {"who": "ann", "times": 2, "tags": ["a", "b"]}
    assert m.validate_request({"who": "ann", "times": "5", "tags": "[c]"}) == {"who": "ann", "times": 5, "tags": ["c"]}
    with pytest.raises(ValueError, match=r"request: missing field 'who' \(str\)"):  # no default: still required
        m.validate_request({"times": 1})
    with pytest.raises(ValueError, match="request field 'times': expected int, got 'many'"):
        m.validate_request({"who": "ann", "times": "many"})
    # each request gets its own copy of a list default
    first = m.validate_request({"who": "a"})
    first["tags"].append("z")
    assert m.validate_request({"who": "b"})["tags"] == ["a", "b"]


@pytest.mark.parametrize(("decl", "col", "message"), [
    ("{type: int, default: three}", 31, "requests.times: default 'three' is not int"),
    ("{type: list, default: 3}", 32, "requests.times: default 3 is not list"),
    ("{type: float, default: .nan}", 33, "requests.times.default"),
    ("{type: int, defualt: 3}", 22, "requests.times: unknown key 'defualt'; did you mean 'default'?"),
])
def test_bad_default_is_a_located_error(tmp_path: Path, decl: str, col: int, message: str) -> None:
    p = write(tmp_path, f"mission: m\nrequests:\n  times: {decl}\ntree:\n  skill: report\n  params: {{message: hi}}\n")
    with pytest.raises(InputError) as ei:
        load_mission(p)
    assert f"{p}:3:{col}: {message}" in str(ei.value), str(ei.value)


def test_validate_command_checks_the_default(run_cli, tmp_path: Path) -> None:
    p = write(tmp_path, MISSION.replace("default: 2", "default: two"))
    res = run_cli("validate", p)
    assert res.rc == 2 and "Traceback" not in res.err
    assert res.err.strip() == f"{p}:4:31: requests.times: default 'two' is not int", res.err
    assert run_cli("validate", write(tmp_path, MISSION, "ok.yaml")).rc == 0


def _runner(tmp_path: Path, mission: str, requests: list[Request]) -> tuple[Runner, Path]:
    log = tmp_path / "run.jsonl"
    out = io.StringIO()
    r = Runner(RunOptions(mission=write(tmp_path, mission), config=write(tmp_path, CONFIG, "c.yaml"),
                          requests=requests, log_path=log), out=out, err=out, progress=Progress(out, enabled=False),
               registry=REGISTRY)
    r.prepare()
    return r, log


def test_run_without_request_serves_the_defaults_once(tmp_path: Path) -> None:
    runner, log = _runner(tmp_path, ALL_DEFAULTS, [])
    assert runner.run() == 0
    assert [res.outcome for res in runner.results] == ["success"]
    assert [r["message"] for r in read_log(log) if r["event"] == "report"] == ["times 2 tags []"]


def test_run_requests_mix_given_and_default_values(tmp_path: Path) -> None:
    reqs = _cli_requests([["times=3"], ["tags=[x, y]"]])  # as `--request times=3 --request tags=[x,y]`
    runner, log = _runner(tmp_path, ALL_DEFAULTS, reqs)
    assert runner.run() == 0
    assert [r["message"] for r in read_log(log) if r["event"] == "report"] == ["times 3 tags []", "times 2 tags ['x', 'y']"]


def test_run_without_request_still_needs_the_required_fields(tmp_path: Path) -> None:
    with pytest.raises(InputError) as ei:
        _runner(tmp_path, MISSION, [])
    assert "mmexec run (no --request given)" in str(ei.value) and "missing field 'who'" in str(ei.value)


def test_serve_submit_leaves_out_a_defaulted_field(tmp_path: Path) -> None:
    mission = load_mission(write(tmp_path, MISSION))
    svc = Service(mission)
    client = TestClient(create_app(svc))
    r = client.post("/api/requests", json={"who": "ann"})
    assert r.status_code == 202 and r.json()["request"] == {"who": "ann", "times": 2, "tags": ["a", "b"]}
    # a list field may come as JSON or as YAML text; a scalar field still may not be a list
    assert svc.submit({"who": "b", "tags": ["c", 1]}).fields["tags"] == ["c", 1]
    assert svc.submit({"who": "b", "tags": "[c]"}).fields["tags"] == ["c"]
    with pytest.raises(ServiceError, match="request field 'times': expected a scalar value"):
        svc.submit({"who": "b", "times": [1]})
    r = client.post("/api/requests", json={"times": 1})
    assert r.status_code == 422 and "missing field 'who'" in r.json()["error"]
    body = client.get("/openapi.json").json()["paths"]["/api/requests"]["post"]["requestBody"]
    assert "one with a default may be left out" in str(body)
    # the request form shows which fields may be left empty, and their defaults
    fields = {f["name"]: f for f in mission_json(mission)["requests"]}
    assert "default" not in fields["who"] and fields["times"]["default"] == 2 and fields["tags"]["default"] == ["a", "b"]


def test_press_buttons_takes_its_buttons_per_request() -> None:
    m = load_mission(REPO / "trees" / "press_buttons.yaml")
    assert "buttons" not in m.params and m.request_fields["buttons"] is list
    assert m.validate_request({}) == {"buttons": []}  # no --request: every button, left to right
    (given,) = _cli_requests([["buttons=[b3,b1]"]])
    assert m.validate_request(given.fields) == {"buttons": ["b3", "b1"]}
    tree = m.instantiate(None, given.fields)
    assert tree.rt.bb["request.buttons"] == ["b3", "b1"]


def test_campaign_draws_some_fields_and_the_rest_take_their_defaults(tmp_path: Path) -> None:
    m, c = write(tmp_path, MISSION), write(tmp_path, CONFIG, "c.yaml")
    # preflight: a drawn request that leaves out a field with no default fails before any trial
    bad = CampaignOptions(mission=m, config=c, trials=2, out=tmp_path / "bad", workers=1, progress=False,
                          requests=RequestPlan(draws={"times": ("1", "3")}))
    with pytest.raises(InputError) as ei:
        run_campaign(bad, out=io.StringIO())
    assert "--draw (trial 0000)" in str(ei.value) and "missing field 'who'" in str(ei.value)
    ok = CampaignOptions(mission=m, config=c, trials=1, out=tmp_path / "ok", workers=1, progress=False,
                         requests=RequestPlan(draws={"who": ("ann",)}))
    _, results = run_campaign(ok, out=io.StringIO())
    assert [r.outcome for r in results] == ["success"], results
    assert "--request who=ann" in results[0].command and "times=" not in results[0].command
    log = Path(results[0].log)
    assert [r["message"] for r in read_log(log) if r["event"] == "report"] == ["ann x2 ['a', 'b']"]


def test_a_list_field_can_be_drawn_its_commas_kept_inside_brackets(tmp_path: Path) -> None:
    assert split_values("1,2,3") == ["1", "2", "3"]
    assert split_values("[b1, b2],[b3],{k: [1, 2]}") == ["[b1, b2]", "[b3]", "{k: [1, 2]}"]
    draws = parse_draws(["who=ann,bo", "tags=[x, y],[z]"], {"backend": "mock"})
    assert draws == {"who": ("ann", "bo"), "tags": ("[x, y]", "[z]")}
    for bad, why in (("tags=[x,y", "tags: unclosed bracket in '[x,y'"),
                     ("tags=x],[y", "tags: unbalanced ']' at character 2 of 'x],[y'")):
        with pytest.raises(InputError) as ei:
            parse_draws([bad], {"backend": "mock"})
        assert str(ei.value) == f"--draw #1: {why}", str(ei.value)
    # each trial gets one whole list, typed by the mission's request field
    m, c = write(tmp_path, MISSION), write(tmp_path, CONFIG, "c.yaml")
    opts = CampaignOptions(mission=m, config=c, trials=2, out=tmp_path / "lists", workers=1, progress=False,
                           requests=RequestPlan(draws=parse_draws(["who=ann", "tags=[x, y],[z]"], {})))
    _, results = run_campaign(opts, out=io.StringIO())
    said = sorted(r["message"] for res in results for r in read_log(Path(res.log)) if r["event"] == "report")
    assert set(said) <= {"ann x2 ['x', 'y']", "ann x2 ['z']"} and len(said) == 2, said


def test_a_request_field_given_as_a_parameter_says_so(tmp_path: Path) -> None:
    m = load_mission(write(tmp_path, MISSION))
    with pytest.raises(ValueError, match=r"'times' is a request field of mission counted, not a parameter "
                                         r"\(give it per request: --request times=\.\.\.\)"):
        m.resolve_params({"times": "3"})
