"""MkDocs hook: put the repository's notebooks (notebooks/*.ipynb) on the site as notebooks/NAME.ipynb.

The notebooks live at the top of the repository, where the test suite executes them; the site renders them
with mkdocs-jupyter (not executed). This hook runs before the plugins' own `on_files`, so mkdocs-jupyter sees
them as it sees files under docs/.
"""

import pathlib

import mkdocs.plugins
from mkdocs.structure.files import File


@mkdocs.plugins.event_priority(100)
def on_files(files, config):
    root = pathlib.Path(config["config_file_path"]).resolve().parent
    for path in sorted((root / "notebooks").glob("*.ipynb")):
        files.append(File(f"notebooks/{path.name}", src_dir=str(root), dest_dir=config["site_dir"],
                          use_directory_urls=config["use_directory_urls"]))
    return files
