# Helpers for .ci/run (sourced): timed steps with their own time limit, package installs, and a
# check that a test selection by name ran what it names.

CI_START=$(date +%s)
STEP_START=$CI_START
STEP_NAME=""
STEP_DEADLINE=0

# step NAME SECONDS: ends the previous step (printing its time and the total so far) and starts
# NAME, whose commands (run through `t`) must all finish within SECONDS of its start.
# `step ""` ends the last step.
step() {
    local now
    now=$(date +%s)
    if [ -n "$STEP_NAME" ]; then
        echo "ci: done in $((now - STEP_START)) s (total $((now - CI_START)) s): $STEP_NAME"
        # Builds fill the disk fast (a linker that runs out of space dies of SIGBUS, which reads
        # like a crash), so each step's end says how much is left.
        echo "ci: disk free: $(df -h --output=avail . | tail -1 | tr -d ' ')"
    fi
    STEP_NAME="$1"
    STEP_START=$now
    STEP_DEADLINE=$((now + ${2:-0}))
    [ -z "$1" ] || echo "ci: $1 (limit ${2} s)"
}

# t COMMAND...: runs COMMAND with what is left of the current step's time; a step that runs out
# fails the whole run, naming the step.
t() {
    local left=$((STEP_DEADLINE - $(date +%s)))
    if [ "$left" -le 0 ]; then
        echo "ci: FAILED: step '$STEP_NAME' ran out of its time" >&2
        return 124
    fi
    local rc=0
    timeout --foreground "$left" "$@" || rc=$?
    if [ "$rc" = 124 ]; then
        echo "ci: FAILED: step '$STEP_NAME' ran out of its time in: $*" >&2
    fi
    return "$rc"
}

# install PACKAGE...: apt-get installs the packages not yet installed (as root, else with sudo).
install() {
    local missing=() p
    for p in "$@"; do
        dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
    done
    [ "${#missing[@]}" -gt 0 ] || return 0
    local sudo=""
    [ "$(id -u)" = 0 ] || sudo="sudo"
    echo "ci: installing ${missing[*]}"
    t $sudo apt-get update -q
    DEBIAN_FRONTEND=noninteractive t $sudo apt-get install -y -q "${missing[@]}"
}

# selected LOG NAME...: fails unless every NAME ran as a test and passed in the cargo test output
# LOG (a step that selects tests by name must not pass by selecting none).
selected() {
    local log="$1" name missing=0
    shift
    for name in "$@"; do
        if ! grep -qE "^test (.*::)?${name} \.\.\. ok$" "$log"; then
            echo "ci: FAILED: the selected test '$name' did not run and pass" >&2
            missing=1
        fi
    done
    return "$missing"
}

# suites_ran LOG COUNT: fails unless LOG shows at least COUNT test binaries that ran a test.
suites_ran() {
    local ran
    ran=$(grep -cE '^test result: ok\. [1-9][0-9]* passed' "$1" || true)
    if [ "$ran" -lt "$2" ]; then
        echo "ci: FAILED: $ran test binaries ran tests, expected at least $2" >&2
        return 1
    fi
}

# modules_ran LOG MODULE...: fails unless every MODULE (a test module of a merged test binary)
# had at least one test pass in LOG; empty names are ignored.
modules_ran() {
    local log="$1" name missing=0
    shift
    for name in "$@"; do
        [ -n "$name" ] || continue
        if ! grep -qE "^test ${name}::.* \.\.\. ok$" "$log"; then
            echo "ci: FAILED: no test of the suite '$name' ran and passed" >&2
            missing=1
        fi
    done
    return "$missing"
}
