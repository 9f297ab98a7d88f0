"""Fixtures of the service tests: an app on a temporary SQLite store, with real worker processes;
and the job store on both backends (``store_url``): SQLite in a temporary file, and PostgreSQL
when ``CTP_TEST_POSTGRES_URL`` names a database (``.ci/run`` starts one, so CI always runs
them; without it they skip locally, and fail under ``CI=true``). Each PostgreSQL test gets a
schema of its own (dropped afterwards), so runs never see each other's jobs."""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterator
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from service_helpers import settings_for
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url
from sqlalchemy.pool import NullPool

from api.main import create_app

PG_URL = os.environ.get("CTP_TEST_POSTGRES_URL")
#: how to stop and start that server (``.ci/run`` sets it: ``pg_ctlcluster 15 main``)
PG_CTL = os.environ.get("CTP_TEST_POSTGRES_CTL")
STORES = ["sqlite", "postgresql"]


def _need_postgres() -> str:
    if not PG_URL:
        if os.environ.get("CI"):
            pytest.fail("CTP_TEST_POSTGRES_URL is not set: .ci/run must start PostgreSQL for these tests")
        pytest.skip("set CTP_TEST_POSTGRES_URL=postgresql+psycopg://... to test the store on PostgreSQL")
    return PG_URL


def new_store_url(kind: str, tmp: Path) -> Iterator[str]:
    """A fresh, empty store of ``kind``: a SQLite file in ``tmp``, or a new PostgreSQL schema."""
    if kind == "sqlite":
        yield f"sqlite:///{tmp / 'jobs.db'}"
        return
    base = _need_postgres()
    schema = f"ctp_test_{uuid.uuid4().hex[:12]}"
    admin = create_engine(base, poolclass=NullPool)  # a new connection each time: the server may restart
    with admin.begin() as c:
        c.execute(text(f"CREATE SCHEMA {schema}"))
    url = make_url(base).update_query_dict({"options": f"-csearch_path={schema}"})
    try:
        yield url.render_as_string(hide_password=False)
    finally:
        with admin.begin() as c:
            c.execute(text(f"DROP SCHEMA IF EXISTS {schema} CASCADE"))
        admin.dispose()


@pytest.fixture(params=STORES)
def store_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    yield from new_store_url(request.param, tmp_path)


@pytest.fixture
def pg_store_url(tmp_path: Path) -> Iterator[str]:
    """A fresh PostgreSQL store only (tests of what SQLite has no counterpart for)."""
    yield from new_store_url("postgresql", tmp_path)


@pytest.fixture(scope="module", params=STORES)
def store_client(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    """The service (real workers, tight limits) on each store in turn."""
    for url in new_store_url(request.param, tmp_path_factory.mktemp(f"svc-{request.param}")):
        app = create_app(settings_for(tmp_path_factory.mktemp("unused"), database_url=url, max_contacts=9,
                                      job_time_limit=60.0))
        with TestClient(app) as c:
            yield c


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    app = create_app(settings_for(tmp_path_factory.mktemp("api")))
    with TestClient(app) as c:
        yield c
