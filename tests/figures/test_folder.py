"""``--plots DIR``: an existing folder is used, a missing one made, anything else refused naming it."""

from __future__ import annotations

import pytest

from wavestack.figures import check_plot_folder
from wavestack.pipeline import InputError


def test_existing_and_missing_folders(tmp_path) -> None:
    assert check_plot_folder(tmp_path, "--plots") == tmp_path
    made = check_plot_folder(tmp_path / "new", "--plots")
    assert made.is_dir()


@pytest.mark.parametrize("make, fragment", [
    (lambda p: (p / "file").write_text("x") and p / "file", "names a file, not a folder"),
    (lambda p: p / "no" / "such", "parent folder"),
    (lambda p: "", "expected a folder path"),
])
def test_refused_paths_name_the_option(tmp_path, make, fragment) -> None:
    with pytest.raises(InputError, match=fragment) as caught:
        check_plot_folder(make(tmp_path), "--plots")
    assert "--plots" in str(caught.value)
