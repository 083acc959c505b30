#!/usr/bin/env bash
# A small lab's stack on one machine, all on 127.0.0.1: munge, a one-node SLURM cluster
# (slurmctld + slurmd), PostgreSQL, and an MLflow tracking server on that database with
# proxied artifacts. CI starts it before the slow tests; a lab can read it as a recipe for a
# small server (on several machines: the same slurm.conf everywhere, one munge key, the
# database and `mlflow server` reachable from the nodes instead of loopback only).
#
#   ci/lab_stack.sh start [munge|slurm|postgres|mlflow]   start what is not running (idempotent)
#   ci/lab_stack.sh stop  [munge|slurm|postgres|mlflow]   stop what runs
#   ci/lab_stack.sh status                                 what runs, one line each; exit 1 if not all
#   ci/lab_stack.sh env                                    where jobs log (eval "$(...)")
#
# Needs root (daemons, /etc/slurm/slurm.conf). Installs Debian's slurm-wlm, munge and postgresql
# when missing, and psycopg into the Python environment when missing. Everything variable lives
# under $LAB_STACK_DIR (default /var/tmp/tactile_exp-lab): the database cluster, the artifacts,
# SLURM's spool folders, the logs and the process ids.
set -euo pipefail

REPO=$(cd "$(dirname "$0")/.." && pwd)
LAB=${LAB_STACK_DIR:-/var/tmp/tactile_exp-lab}
PYTHON=${LAB_STACK_PYTHON:-$REPO/.venv/bin/python}  # the environment `mlflow server` runs in
PG_PORT=${LAB_PG_PORT:-55432}
MLFLOW_PORT=${LAB_MLFLOW_PORT:-5055}
DB=mlflow STUDY_DB=optuna DB_USER=mlflow DB_PASSWORD=${LAB_DB_PASSWORD:-mlflow}  # loopback only; a lab sets its own
PARTITION=debug
SLURM_CONF=/etc/slurm/slurm.conf
MARKER="# written by tactile_exp ci/lab_stack.sh"  # only such a slurm.conf is ever rewritten
PG_BIN=$(ls -d /usr/lib/postgresql/*/bin 2>/dev/null | sort -V | tail -1 || true)
BACKEND="postgresql+psycopg://$DB_USER:$DB_PASSWORD@127.0.0.1:$PG_PORT/$DB"  # psycopg 3's driver
STUDY_STORAGE="postgresql+psycopg://$DB_USER:$DB_PASSWORD@127.0.0.1:$PG_PORT/$STUDY_DB"  # search=...
TRACKING_URI="http://127.0.0.1:$MLFLOW_PORT"

say() { echo "lab_stack: $*"; }
die() { echo "lab_stack: error: $*" >&2; exit 1; }

wait_for() {  # wait_for SECONDS WHAT COMMAND...: poll until COMMAND succeeds
    local i
    local limit=$1 what=$2; shift 2
    for ((i = 0; i < limit * 4; i++)); do
        "$@" >/dev/null 2>&1 && return 0
        sleep 0.25
    done
    die "$what did not come up in ${limit}s (logs in $LAB/log)"
}

install_packages() {
    local missing=()
    command -v munged >/dev/null || missing+=(munge)
    command -v slurmctld >/dev/null || missing+=(slurm-wlm)
    [ -n "$PG_BIN" ] || missing+=(postgresql)
    if ((${#missing[@]})); then
        say "installing ${missing[*]} (Debian packages)"
        apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >/dev/null
        PG_BIN=$(ls -d /usr/lib/postgresql/*/bin | sort -V | tail -1)
    fi
    "$PYTHON" -c "import psycopg" 2>/dev/null || "$PYTHON" -m pip install --quiet "psycopg[binary]"
}

# --- munge: SLURM's authentication (one shared key per cluster) -----------------------------
munge_up() { munge -n 2>/dev/null | unmunge >/dev/null 2>&1; }
start_munge() {
    munge_up && return
    [ -s /etc/munge/munge.key ] || { mungekey --create 2>/dev/null || create-munge-key -f; }
    chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
    install -d -o munge -g munge -m 0755 /run/munge /var/lib/munge /var/log/munge
    runuser -u munge -- munged
    wait_for 10 munged munge_up
}
stop_munge() { [ -f /run/munge/munged.pid ] && kill "$(cat /run/munge/munged.pid)" 2>/dev/null || true; }

# --- SLURM: one node (this host), one partition with its CPUs --------------------------------
write_slurm_conf() {
    if [ -f "$SLURM_CONF" ] && ! grep -qF "$MARKER" "$SLURM_CONF"; then
        die "$SLURM_CONF exists and was not written by this script; not touching it"
    fi
    local cpus mem
    cpus=$(nproc)
    mem=$(awk '/MemTotal/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)  # MB, leaving the OS some
    cat >"$SLURM_CONF" <<EOF
$MARKER
ClusterName=lab
SlurmctldHost=$(hostname -s)(127.0.0.1)
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$LAB/slurm/state
SlurmdSpoolDir=$LAB/slurm/spool
SlurmctldPidFile=$LAB/run/slurmctld.pid
SlurmdPidFile=$LAB/run/slurmd.pid
SlurmctldLogFile=$LAB/log/slurmctld.log
SlurmdLogFile=$LAB/log/slurmd.log
# No cgroups (containers and CI machines often lack them): processes tracked through /proc.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
# No accounting database (slurmdbd): sacct is unavailable, squeue and scontrol work.
AccountingStorageType=accounting_storage/none
JobAcctGatherType=jobacct_gather/none
JobCompType=jobcomp/none
# Jobs share the node by CPU: two 1-CPU jobs run at once on a 2-CPU machine.
SelectType=select/cons_tres
SelectTypeParameters=CR_CPU
# scancel: SIGTERM, then SIGKILL after KillWait seconds (a job marks its runs FAILED meanwhile).
KillWait=10
ReturnToService=2
MpiDefault=none
NodeName=$(hostname -s) NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=$PARTITION Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
}
slurm_up() { sinfo -h -p "$PARTITION" -o %t 2>/dev/null | grep -qE '^(idle|mix|alloc)'; }
start_slurm() {
    slurm_up && return
    install -d "$LAB/slurm/state" "$LAB/slurm/spool" "$LAB/run" "$LAB/log"
    write_slurm_conf
    pgrep -F "$LAB/run/slurmctld.pid" >/dev/null 2>&1 || slurmctld
    wait_for 20 slurmctld scontrol ping
    pgrep -F "$LAB/run/slurmd.pid" >/dev/null 2>&1 || slurmd
    wait_for 30 "slurmd (node $(hostname -s))" slurm_up
}
stop_slurm() {
    local name i
    for name in slurmd slurmctld; do
        [ -f "$LAB/run/$name.pid" ] || continue
        kill "$(cat "$LAB/run/$name.pid")" 2>/dev/null || true
        for ((i = 0; i < 40; i++)); do pgrep -F "$LAB/run/$name.pid" >/dev/null 2>&1 || break; sleep 0.25; done
        rm -f "$LAB/run/$name.pid"
    done
}

# --- PostgreSQL: a cluster of its own under $LAB/postgres, password login on loopback --------
pg() { runuser -u postgres -- "$PG_BIN/$1" "${@:2}"; }
postgres_up() { pg pg_isready -q -h 127.0.0.1 -p "$PG_PORT"; }
start_postgres() {
    if ! postgres_up; then
        install -d -o postgres -g postgres -m 0700 "$LAB/postgres"
        install -d -o postgres -g postgres "$LAB/log/postgres"
        if [ ! -f "$LAB/postgres/PG_VERSION" ]; then
            pg initdb -D "$LAB/postgres" -U postgres --auth-local=peer --auth-host=scram-sha-256 >/dev/null
        fi
        pg pg_ctl -D "$LAB/postgres" -l "$LAB/log/postgres/server.log" -w \
            -o "-c listen_addresses=127.0.0.1 -c port=$PG_PORT -k /tmp" start >/dev/null
        wait_for 20 postgres postgres_up
    fi
    # Once: the role, MLflow's database and the searches' study database (Optuna's tables apart
    # from MLflow's: both keep an alembic_version table).
    local psql=(pg psql -q -h /tmp -p "$PG_PORT" -U postgres -v ON_ERROR_STOP=1) db
    if [ -z "$("${psql[@]}" -tAc "SELECT 1 FROM pg_roles WHERE rolname = '$DB_USER'")" ]; then
        "${psql[@]}" -c "CREATE ROLE $DB_USER LOGIN PASSWORD '$DB_PASSWORD'"
    fi
    for db in "$DB" "$STUDY_DB"; do
        if [ -z "$("${psql[@]}" -tAc "SELECT 1 FROM pg_database WHERE datname = '$db'")" ]; then
            "${psql[@]}" -c "CREATE DATABASE $db OWNER $DB_USER"
        fi
    done
}
stop_postgres() {
    [ -f "$LAB/postgres/postmaster.pid" ] || return 0
    pg pg_ctl -D "$LAB/postgres" -m fast -w stop >/dev/null || true
}

# --- MLflow: the tracking server on the database, artifacts proxied (mlflow-artifacts:/) ----
mlflow_up() { curl -sf "$TRACKING_URI/health" >/dev/null; }
start_mlflow() {
    mlflow_up && return
    install -d "$LAB/artifacts" "$LAB/run" "$LAB/log"
    # Two workers for a 2-core machine; MLflow's own database migrations run on first start.
    MLFLOW_DISABLE_TELEMETRY=true setsid "$PYTHON" -m mlflow server \
        --backend-store-uri "$BACKEND" --serve-artifacts --artifacts-destination "$LAB/artifacts" \
        --host 127.0.0.1 --port "$MLFLOW_PORT" --workers 2 \
        >>"$LAB/log/mlflow.log" 2>&1 </dev/null &
    echo $! >"$LAB/run/mlflow.pid"
    wait_for 180 "mlflow server" mlflow_up
}
stop_mlflow() {
    [ -f "$LAB/run/mlflow.pid" ] || return 0
    local pid i
    pid=$(cat "$LAB/run/mlflow.pid")
    kill -TERM -- "-$pid" 2>/dev/null || true  # its process group: the server and its workers
    for ((i = 0; i < 60; i++)); do kill -0 "$pid" 2>/dev/null || break; sleep 0.25; done
    kill -KILL -- "-$pid" 2>/dev/null || true
    rm -f "$LAB/run/mlflow.pid"
}

status() {
    local ok=0
    munge_up && say "munge: up" || { say "munge: down"; ok=1; }
    slurm_up && say "slurm: partition $PARTITION up ($(sinfo -h -p $PARTITION -o '%D node, %c CPUs'))" \
        || { say "slurm: down"; ok=1; }
    postgres_up && say "postgres: up on 127.0.0.1:$PG_PORT" || { say "postgres: down"; ok=1; }
    mlflow_up && say "mlflow: up at $TRACKING_URI (backend $BACKEND)" || { say "mlflow: down"; ok=1; }
    return $ok
}

ALL=(munge slurm postgres mlflow)
command=${1:-status}
shift || true
parts=("${@:-${ALL[@]}}")
case $command in
start)
    [ "$(id -u)" = 0 ] || die "start needs root (daemons and $SLURM_CONF)"
    begin=$(date +%s%N)
    install_packages
    for part in "${parts[@]}"; do
        t=$(date +%s%N)
        "start_$part"
        ms=$((($(date +%s%N) - t) / 1000000))
        say "$part up ($((ms / 1000)).$((ms % 1000 / 100)) s)"
    done
    ms=$((($(date +%s%N) - begin) / 1000000))
    say "started ${parts[*]} in $((ms / 1000)).$((ms % 1000 / 100)) s"
    ;;
stop)
    for ((i = ${#parts[@]} - 1; i >= 0; i--)); do "stop_${parts[i]}"; done
    say "stopped ${parts[*]}"
    ;;
status) status ;;
env)
    echo "export MLFLOW_TRACKING_URI=$TRACKING_URI"
    echo "# a search's study storage: hydra.sweeper.storage=$STUDY_STORAGE"
    ;;
*) die "usage: $0 start|stop|status|env [munge|slurm|postgres|mlflow ...]" ;;
esac
