"""Fuzz every operation of the OpenAPI document against the live server: never a 5xx.

schemathesis generates valid and invalid requests from the schema (bounded: 50 examples per
operation) and runs its default checks: no server error, invalid data rejected with a 4xx, and
responses that conform to the documented status codes, content types and schemas. One check is
left out: ``positive_data_acceptance`` expects every schema-valid request to succeed, but a
schema cannot say "a decodable image" or "a configured camera name", so a 422 there is right. The document is the app's own
(``create_app().openapi()``, no server needed at collection); the requests go to the live
server.
"""

from __future__ import annotations

import hypothesis
import pytest
import schemathesis
from schemathesis.specs.openapi.checks import positive_data_acceptance

from service.api import Settings, create_app

from .conftest import LiveServer

schema = schemathesis.openapi.from_dict(create_app(Settings(host="127.0.0.1", api_key=None)).openapi())
OPERATIONS = {op.label: op for op in (result.ok() for result in schema.get_all_operations())}
"""Every operation by label (``POST /v1/solve``): a test id each. schemathesis's own
``schema.parametrize()`` gives its items one shared node id, which pytest-xdist runs once."""


@pytest.mark.parametrize("label", sorted(OPERATIONS))
def test_no_server_errors(label: str, server: LiveServer) -> None:
    @hypothesis.given(case=OPERATIONS[label].as_strategy())
    @hypothesis.settings(max_examples=50, deadline=None, derandomize=True, database=None,
                         suppress_health_check=list(hypothesis.HealthCheck))
    def fuzz(case: schemathesis.Case) -> None:
        case.call_and_validate(base_url=server.url, excluded_checks=[positive_data_acceptance])

    fuzz()


def test_every_operation_is_fuzzed() -> None:
    assert len(OPERATIONS) >= 5 and "POST /v1/solve" in OPERATIONS, sorted(OPERATIONS)
