"""docs/reference.md is what tests/support/reference_doc.py generates from the code (declarations,
RenderSettings, the command-line parser): a change there without regenerating the page fails here."""

import os

from tests.conftest import REPO
from tests.support.reference_doc import PATH, generate


def test_reference_page_is_current():
    with open(PATH, encoding="utf-8") as fh:
        written = fh.read()
    assert written == generate(), (f"{os.path.relpath(PATH, REPO)} is stale: run "
                                   "`python tests/support/reference_doc.py` and commit the result")
