# Sourced by scripts/*: creates .venv with the project installed (editable) when it is missing or
# older than pyproject.toml. Needs only Python >= 3.11 with venv.
bootstrap_venv() {
  local extras="${1:-}"
  local stamp=".venv/.installed${extras:+-$extras}"
  local python="${PYTHON:-python3}"
  if ! "$python" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
    echo "error: Python >= 3.11 is needed ($python is $("$python" --version 2>&1))" >&2
    exit 1
  fi
  if [ ! -x .venv/bin/python ]; then
    echo "== creating .venv"
    "$python" -m venv .venv
  fi
  if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
    echo "== installing the project into .venv"
    .venv/bin/python -m pip install --quiet --upgrade pip
    .venv/bin/python -m pip install --quiet -e ".${extras:+[$extras]}"
    touch "$stamp"
  fi
  # Bytecode for the project's own modules (an editable install has none): with
  # PYTHONDONTWRITEBYTECODE set, every start of a service would compile them again. Stale files
  # are never used (Python checks each one against its source), so this only saves start-up.
  .venv/bin/python -m compileall -q src >/dev/null
}
