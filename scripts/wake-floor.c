// What one paced wake-up of a blocked receiver costs this machine at the least, by
// mechanism, with nothing of ours in it (the floor under samples-bench's blocking
// receivers; docs/benchmarks.md, "Targets"):
//
//   udp   the sender writes 120 bytes to a loopback UDP socket, the receiver blocks
//         in recv (samples-bench's udp-blk);
//   dgram the sender stores the stamp in shared memory and writes one byte to a
//         Unix datagram socket; the receiver waits in epoll_wait and reads the byte
//         on its next round (skymesh's blocking receive over iceoryx2's event:
//         two system calls per message);
//   sem   the sender stores the stamp and posts a process-shared semaphore; the
//         receiver blocks in sem_wait (a futex: iceoryx2's semaphore event, which
//         has no file descriptor).
//
//   gcc -O2 -o /tmp/wake-floor scripts/wake-floor.c
//   for m in udp dgram sem; do /tmp/wake-floor $m 1000 3000; /tmp/wake-floor $m 100 400; done
//
// Latency = receive time - send stamp (CLOCK_MONOTONIC); the first tenth of the
// messages is not counted. CPU per message = CLOCK_PROCESS_CPUTIME_ID of each side
// over the run / messages.
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <semaphore.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/epoll.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#define MAX_MSGS 20000

static uint64_t now(clockid_t c) {
    struct timespec t;
    clock_gettime(c, &t);
    return (uint64_t)t.tv_sec * 1000000000ull + (uint64_t)t.tv_nsec;
}

struct shared {
    sem_t sem;
    _Atomic uint64_t stamp;
    _Atomic uint64_t seq;
    uint64_t rx_cpu;
    uint64_t lat[MAX_MSGS];
};

static int cmp(const void *a, const void *b) {
    uint64_t x = *(const uint64_t *)a, y = *(const uint64_t *)b;
    return x < y ? -1 : x > y;
}

int main(int argc, char **argv) {
    if (argc != 4) {
        fprintf(stderr, "usage: %s udp|dgram|sem HZ MESSAGES\n", argv[0]);
        return 64;
    }
    const char *mode = argv[1];
    int udp = !strcmp(mode, "udp"), dgram = !strcmp(mode, "dgram"), sem = !strcmp(mode, "sem");
    double hz = atof(argv[2]);
    int n = atoi(argv[3]);
    if (!(udp || dgram || sem) || hz <= 0 || n < 10 || n > MAX_MSGS) {
        fprintf(stderr, "bad arguments\n");
        return 64;
    }
    struct shared *s = mmap(0, sizeof *s, PROT_READ | PROT_WRITE, MAP_SHARED | MAP_ANONYMOUS, -1, 0);
    sem_init(&s->sem, 1, 0);
    int pair[2];
    socketpair(AF_UNIX, SOCK_DGRAM, 0, pair);
    int rx_udp = socket(AF_INET, SOCK_DGRAM, 0);
    struct sockaddr_in addr = {.sin_family = AF_INET, .sin_addr.s_addr = htonl(INADDR_LOOPBACK)};
    socklen_t len = sizeof addr;
    bind(rx_udp, (struct sockaddr *)&addr, sizeof addr);
    getsockname(rx_udp, (struct sockaddr *)&addr, &len);

    pid_t child = fork();
    if (child == 0) {
        uint64_t c0 = now(CLOCK_PROCESS_CPUTIME_ID);
        int ep = epoll_create1(0);
        if (dgram) {
            fcntl(pair[1], F_SETFL, fcntl(pair[1], F_GETFL) | O_NONBLOCK);
            struct epoll_event ev = {.events = EPOLLIN};
            epoll_ctl(ep, EPOLL_CTL_ADD, pair[1], &ev);
        }
        char buf[128];
        int pending = 0;
        for (int i = 0; i < n; i++) {
            uint64_t stamp;
            if (udp) {
                recv(rx_udp, buf, sizeof buf, 0);
                memcpy(&stamp, buf, sizeof stamp);
            } else if (dgram) {
                for (;;) {
                    // The last wake-up's byte, read before looking (as the runtime does).
                    if (pending) {
                        recv(pair[1], buf, sizeof buf, 0);
                        pending = 0;
                    }
                    if (atomic_load(&s->seq) > (uint64_t)i) break;
                    struct epoll_event e;
                    epoll_wait(ep, &e, 1, -1);
                    pending = 1;
                    if (atomic_load(&s->seq) > (uint64_t)i) break;
                }
                stamp = atomic_load(&s->stamp);
            } else {
                while (atomic_load(&s->seq) <= (uint64_t)i) sem_wait(&s->sem);
                stamp = atomic_load(&s->stamp);
            }
            s->lat[i] = now(CLOCK_MONOTONIC) - stamp;
        }
        s->rx_cpu = now(CLOCK_PROCESS_CPUTIME_ID) - c0;
        _exit(0);
    }
    usleep(100000);
    uint64_t c0 = now(CLOCK_PROCESS_CPUTIME_ID);
    uint64_t base = now(CLOCK_MONOTONIC), period = (uint64_t)(1e9 / hz);
    for (int i = 0; i < n; i++) {
        uint64_t due = base + (uint64_t)(i + 1) * period;
        struct timespec d = {(time_t)(due / 1000000000ull), (long)(due % 1000000000ull)};
        clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &d, 0);
        uint64_t stamp = now(CLOCK_MONOTONIC);
        if (udp) {
            char msg[120] = {0};
            memcpy(msg, &stamp, sizeof stamp);
            sendto(rx_udp, msg, sizeof msg, 0, (struct sockaddr *)&addr, sizeof addr);
        } else {
            atomic_store(&s->stamp, stamp);
            atomic_store(&s->seq, (uint64_t)i + 1);
            if (dgram)
                send(pair[0], "x", 1, MSG_DONTWAIT);
            else
                sem_post(&s->sem);
        }
    }
    uint64_t tx_cpu = now(CLOCK_PROCESS_CPUTIME_ID) - c0;
    waitpid(child, 0, 0);
    int skip = n / 10, m = n - skip;
    uint64_t *l = s->lat + skip;
    qsort(l, (size_t)m, sizeof *l, cmp);
    printf("%-6s %6.0f Hz  p50 %6.1f  p99 %6.1f us   CPU per message: tx %5.1f  rx %5.1f us\n", mode, hz,
           l[m / 2] / 1e3, l[m * 99 / 100] / 1e3, tx_cpu / 1e3 / n, s->rx_cpu / 1e3 / n);
    return 0;
}
