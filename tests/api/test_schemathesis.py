"""Property-based tests of the whole HTTP API from its OpenAPI schema (schemathesis): whatever
the generated request, the service answers without a server error (no 5xx), and its responses
conform to the documented status codes and schemas. Bounded: a few examples per operation."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis.checks import not_a_server_error
from schemathesis.specs.openapi.checks import response_schema_conformance, status_code_conformance

from api.main import create_app
from api.settings import Settings

_TMP = Path(tempfile.mkdtemp(prefix="ctp-schemathesis-"))
# jobs are accepted and stored but not run (run_jobs=False): the HTTP surface is under test here
app = create_app(Settings(database_url=f"sqlite:///{_TMP / 'jobs.db'}", data_dir=_TMP / "data",
                          analysis_workers=1, job_workers=1,
                          run_jobs=False, request_time_limit=10.0))
schema = schemathesis.openapi.from_asgi("/openapi.json", app)


@pytest.mark.slow
@schema.parametrize()
@settings(max_examples=12, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
def test_no_server_errors(case: schemathesis.Case) -> None:
    case.call_and_validate(checks=[not_a_server_error, status_code_conformance, response_schema_conformance])
