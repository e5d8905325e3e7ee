"""One set of query defaults: the library's options, ``ViewDB.query``, the CLI, the HTTP form
and the web page agree, so a user gets the same answer wherever they ask."""

import dataclasses
import inspect
import re

import typer

from viewdb import ViewDB
from viewdb.config import DEFAULT_PLAN
from viewdb.http.models import WebQueryFormModel
from viewdb.http.web import STATIC
from viewdb.recognition.options import QueryOptions
from viewdb_cli.main import app

#: Settings each front door takes under the same name as QueryOptions.
SHARED = ("k", "plan", "band", "rotations")


def test_the_library_s_query_signature_has_the_options_defaults():
    options = QueryOptions()
    parameters = inspect.signature(ViewDB.query).parameters
    for name in SHARED:
        assert parameters[name].default == getattr(options, name), name
    assert options.plan == DEFAULT_PLAN


def test_the_cli_query_has_the_options_defaults():
    command = typer.main.get_command(app)
    query = {p.name: p.default for p in command.commands["query"].params}  # type: ignore[attr-defined]
    options = dataclasses.asdict(QueryOptions())
    for name in SHARED:
        assert query[name] == options[name], name


def test_the_http_form_and_the_web_page_default_to_the_library_s_plan_and_k():
    fields = WebQueryFormModel.model_fields
    assert fields["plan"].default == QueryOptions().plan
    assert fields["k"].default == QueryOptions().k
    page = (STATIC / "index.html").read_text()
    selected = re.findall(r'<option value="(\w+)" selected>', page[page.index('id="plan"'):])
    assert selected[:1] == [QueryOptions().plan]
