# mpmctl.bash - bash completion for mpmctl, the client of mpmd.
#
# Completes the commands, each command's options and the global ones, the
# values of --status and --terminal, file names (case files for submit,
# output files for -o, directories for export, --keys and keygen --out),
# and run ids: those `mpmctl runs --json` lists (asked with a 1 s timeout,
# at the --endpoint given on the line, if any; MPMCTL_COMPLETE_RUNS=0 turns
# the query off).
#
# Install: source it from ~/.bashrc, or copy it to
# /usr/share/bash-completion/completions/mpmctl (or
# ~/.local/share/bash-completion/completions/mpmctl).

_mpmctl_runs()
{
    [[ ${MPMCTL_COMPLETE_RUNS:-1} == 0 ]] && return
    local ctl=${COMP_WORDS[0]} ep=() w prev=""
    command -v "$ctl" >/dev/null 2>&1 || return
    # the endpoint from the line as typed: bash splits COMP_WORDS at the
    # colons of tcp://host:port and ipc://path (COMP_WORDBREAKS), so the
    # words are taken from COMP_LINE, split at blanks, quotes removed
    # (ctl_completion checks both forms)
    for w in ${COMP_LINE:-${COMP_WORDS[*]}}; do
        w=${w//\'/}
        w=${w//\"/}
        [[ $prev == --endpoint ]] && ep=(--endpoint "$w")
        [[ $w == --endpoint=* ]] && ep=(--endpoint "${w#--endpoint=}")
        prev=$w
    done
    "$ctl" "${ep[@]}" --timeout 1 runs --json 2>/dev/null |
        sed -n 's/.*"runId": *"\{0,1\}\([0-9][0-9]*\).*/\1/p'
}

_mpmctl()
{
    local cur=${COMP_WORDS[COMP_CWORD]} prev=""
    ((COMP_CWORD > 0)) && prev=${COMP_WORDS[COMP_CWORD - 1]}
    local commands="submit watch runs show energy snapshot export plot resume cancel ping version keygen"
    local global="--endpoint --stream --timeout --keys --help"
    local withval="--endpoint --stream --timeout --keys --status --limit --before --step -o --out --name --terminal --format"
    COMPREPLY=()

    # the value of an option
    case $prev in
    --status)
        COMPREPLY=($(compgen -W "QUEUED RUNNING FINISHED FAILED CANCELLED INTERRUPTED" -- "$cur"))
        return ;;
    --terminal)
        COMPREPLY=($(compgen -W "pngcairo png svg pdfcairo" -- "$cur"))
        return ;;
    --format)
        COMPREPLY=($(compgen -W "vtk hdf5" -- "$cur"))
        return ;;
    --keys)
        COMPREPLY=($(compgen -d -- "$cur"))
        return ;;
    -o | --out)
        local w
        for w in "${COMP_WORDS[@]}"; do
            if [[ $w == keygen ]]; then
                COMPREPLY=($(compgen -d -- "$cur"))
                return
            fi
        done
        COMPREPLY=($(compgen -f -- "$cur"))
        return ;;
    --endpoint | --stream | --timeout | --limit | --before | --step | --name)
        return ;;
    esac

    # the command and the positional arguments before the cursor
    local cmd="" npos=0 i w
    for ((i = 1; i < COMP_CWORD; i++)); do
        w=${COMP_WORDS[i]}
        if [[ $w == -* ]]; then
            [[ " $withval " == *" $w "* ]] || continue
            ((i++))
            # a value bash split at its colons (tcp://host:port): its pieces
            while ((i + 1 < COMP_CWORD)) && [[ ${COMP_WORDS[i + 1]} == : || ${COMP_WORDS[i]} == : ]]; do
                ((i++))
            done
        elif [[ -z $cmd ]]; then
            cmd=$w
        else
            ((npos++))
        fi
    done

    if [[ -z $cmd ]]; then
        if [[ $cur == -* ]]; then
            COMPREPLY=($(compgen -W "$global" -- "$cur"))
        else
            COMPREPLY=($(compgen -W "$commands" -- "$cur"))
        fi
        return
    fi

    local opts
    case $cmd in
    submit | resume) opts="--watch --csv --json --quiet" ;;
    watch | energy) opts="--csv --json" ;;
    runs) opts="--status --limit --before --all --json" ;;
    show) opts="--json --case" ;;
    snapshot) opts="--step -o --ascii --base64 --compress" ;;
    export) opts="--format --grid --ascii --base64 --compress" ;;
    plot) opts="-o --terminal" ;;
    cancel | ping | version) opts="--json" ;;
    keygen) opts="--out --name" ;;
    *) return ;;
    esac
    if [[ $cur == -* ]]; then
        COMPREPLY=($(compgen -W "$opts $global" -- "$cur"))
        return
    fi
    case $cmd in
    submit)
        ((npos == 0)) && COMPREPLY=($(compgen -f -X '!*.json' -- "$cur") $(compgen -d -S / -- "$cur"))
        ;;
    watch | show | energy | snapshot | plot | resume | cancel)
        ((npos == 0)) && COMPREPLY=($(compgen -W "$(_mpmctl_runs)" -- "$cur"))
        ;;
    export)
        if ((npos == 0)); then
            COMPREPLY=($(compgen -W "$(_mpmctl_runs)" -- "$cur"))
        elif ((npos == 1)); then
            COMPREPLY=($(compgen -d -- "$cur"))
        fi
        ;;
    esac
}

complete -o filenames -F _mpmctl mpmctl
