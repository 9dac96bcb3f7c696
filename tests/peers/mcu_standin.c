/*
 * A microcontroller stand-in for micros_rt's mcu-bridge: what firmware on a motor or sensor board would
 * do, in C, with Debian's libmsgpack-dev (seed 003, the CVRA ROS MessagePack bridge).
 *
 * It speaks one form (--form), as a real board does, and understands nothing else:
 *    cvra (default): CVRA's final cvra_rpc (message.c/service_call.c: an array of exactly 2) -- a datagram or
 *                    request is [name, args], args one object; it writes its Imu as [name, {fields}] and its
 *                    calls as [name, [--call-arg values...]] (or [name, nil] without);
 *    readme:         the seed README's -- a topic datagram is name then {fields}, and so is a service request
 *                    (two objects in one serial datagram; its calls map each --call-key to its --call-arg).
 * --array-form writes its Imu datagrams as [name, field1, ...] instead (nested messages as arrays too).
 *  - streams sensor_msgs/Imu datagrams ("imu") to the bridge at --rate Hz, optionally pausing once
 *    (--pause-after N --pause SECONDS);
 *  - prints every datagram it receives (e.g. geometry_msgs/Twist commands) as a JSON line with each
 *    field and the IP TOS it arrived with (name and fields null when the datagram is not in its form);
 *  - serves one service (--service-name, default "reset", std_srvs/Trigger's response) on its TCP
 *    service port: a serial datagram (SLIP + CRC32 big-endian) in, a MessagePack map out, then close;
 *    (--hang-name NAME: a call of NAME is never answered, the board holds the connection up to 3 s);
 *    a request not in its form is a bad_frame event and gets no answer;
 *  - can call a service through the bridge (--call NAME [--call-arg VALUE]... --call-after SECONDS).
 *
 * Build: gcc -O2 -Wall -o mcu_standin mcu_standin.c -lmsgpackc
 * Every event is one JSON object per line on stdout: ready, recv, served, bad_frame, call_result,
 * paused, resumed, done.
 */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <math.h>
#include <msgpack.h>
#include <netinet/in.h>
#include <poll.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#define END 0xC0
#define ESC 0xDB
#define ESC_END 0xDC
#define ESC_ESC 0xDD
#define MAX_FRAME 65536
#define MAX_ARGS 8

static volatile sig_atomic_t stop_requested = 0;
static void on_signal(int sig) { (void)sig; stop_requested = 1; }

struct options {
    const char *address, *bridge, *stream_name, *service_name, *hang_name, *call_name;
    const char *call_args[MAX_ARGS];
    const char *call_keys[MAX_ARGS];
    int n_call_args, n_call_keys;
    int topic_port, service_port, bridge_topic_port, bridge_service_port;
    double rate, duration, pause, call_after, linger;
    long count, pause_after;
    int form, array_form;
};

enum { FORM_CVRA = 0, FORM_README = 1 };

static double now_mono(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec + ts.tv_nsec / 1e9;
}

/* ------------------------------------------------------------------ CRC32 and SLIP */

static uint32_t crc32_ieee(const unsigned char *p, size_t n) {
    uint32_t crc = 0xFFFFFFFFu;
    for (size_t i = 0; i < n; i++) {
        crc ^= p[i];
        for (int k = 0; k < 8; k++) crc = (crc >> 1) ^ (0xEDB88320u & (0u - (crc & 1u)));
    }
    return ~crc;
}

/* payload + CRC32 (big-endian), escaped, END; returns the frame length (out needs 2 * n + 9 bytes) */
static size_t slip_frame(const unsigned char *payload, size_t n, unsigned char *out) {
    unsigned char tail[4];
    uint32_t crc = crc32_ieee(payload, n);
    tail[0] = crc >> 24; tail[1] = crc >> 16; tail[2] = crc >> 8; tail[3] = crc;
    size_t o = 0;
    for (size_t i = 0; i < n + 4; i++) {
        unsigned char b = i < n ? payload[i] : tail[i - n];
        if (b == END) { out[o++] = ESC; out[o++] = ESC_END; }
        else if (b == ESC) { out[o++] = ESC; out[o++] = ESC_ESC; }
        else out[o++] = b;
    }
    out[o++] = END;
    return o;
}

/* frame body (before END) -> payload in place; returns payload length or -1 (bad escape/CRC) */
static long slip_unframe(unsigned char *buf, size_t n) {
    size_t o = 0;
    for (size_t i = 0; i < n; i++) {
        if (buf[i] == ESC) {
            if (++i >= n) return -1;
            if (buf[i] == ESC_END) buf[o++] = END;
            else if (buf[i] == ESC_ESC) buf[o++] = ESC;
            else return -1;
        } else buf[o++] = buf[i];
    }
    if (o < 4) return -1;
    uint32_t got = ((uint32_t)buf[o - 4] << 24) | ((uint32_t)buf[o - 3] << 16) | ((uint32_t)buf[o - 2] << 8) | buf[o - 1];
    if (got != crc32_ieee(buf, o - 4)) return -1;
    return (long)(o - 4);
}

/* ------------------------------------------------------------------ JSON output */

static void json_string(const char *p, size_t n) {
    putchar('"');
    for (size_t i = 0; i < n; i++) {
        unsigned char c = (unsigned char)p[i];
        if (c == '"' || c == '\\') printf("\\%c", c);
        else if (c < 0x20) printf("\\u%04x", c);
        else putchar(c);
    }
    putchar('"');
}

static void json_object(const msgpack_object *o) {
    switch (o->type) {
    case MSGPACK_OBJECT_NIL: printf("null"); break;
    case MSGPACK_OBJECT_BOOLEAN: printf(o->via.boolean ? "true" : "false"); break;
    case MSGPACK_OBJECT_POSITIVE_INTEGER: printf("%llu", (unsigned long long)o->via.u64); break;
    case MSGPACK_OBJECT_NEGATIVE_INTEGER: printf("%lld", (long long)o->via.i64); break;
    case MSGPACK_OBJECT_FLOAT32:
    case MSGPACK_OBJECT_FLOAT64:
        if (isfinite(o->via.f64)) printf("%.17g", o->via.f64); else printf("null");
        break;
    case MSGPACK_OBJECT_STR: json_string(o->via.str.ptr, o->via.str.size); break;
    case MSGPACK_OBJECT_BIN:
        printf("{\"bin\": [");
        for (uint32_t i = 0; i < o->via.bin.size; i++) printf(i ? ", %u" : "%u", (unsigned char)o->via.bin.ptr[i]);
        printf("]}");
        break;
    case MSGPACK_OBJECT_ARRAY:
        putchar('[');
        for (uint32_t i = 0; i < o->via.array.size; i++) {
            if (i) printf(", ");
            json_object(&o->via.array.ptr[i]);
        }
        putchar(']');
        break;
    case MSGPACK_OBJECT_MAP:
        putchar('{');
        for (uint32_t i = 0; i < o->via.map.size; i++) {
            const msgpack_object *k = &o->via.map.ptr[i].key;
            if (i) printf(", ");
            if (k->type == MSGPACK_OBJECT_STR) json_string(k->via.str.ptr, k->via.str.size);
            else printf("\"?\"");
            printf(": ");
            json_object(&o->via.map.ptr[i].val);
        }
        putchar('}');
        break;
    default: printf("\"(ext)\""); break;
    }
}

/* ------------------------------------------------------------------ the Imu stream */

static void pack_str(msgpack_packer *pk, const char *s) {
    size_t n = strlen(s);
    msgpack_pack_str(pk, n);
    msgpack_pack_str_body(pk, s, n);
}

static void pack_key(msgpack_packer *pk, const char *key, int array_form) {
    if (!array_form) pack_str(pk, key);
}

static void pack_vector(msgpack_packer *pk, int array_form, const char **keys, const double *v, int n) {
    if (array_form) msgpack_pack_array(pk, n); else msgpack_pack_map(pk, n);
    for (int i = 0; i < n; i++) {
        pack_key(pk, keys[i], array_form);
        msgpack_pack_double(pk, v[i]);
    }
}

static void pack_covariance(msgpack_packer *pk, double diag) {
    msgpack_pack_array(pk, 9);
    for (int i = 0; i < 9; i++) msgpack_pack_double(pk, i % 4 == 0 ? diag : 0.0);
}

/* One sensor_msgs/Imu datagram: sample i, stamped with the wall clock. */
static void pack_imu(msgpack_packer *pk, const char *name, long i, int form, int array_form) {
    static const char *xyz[] = {"x", "y", "z"};
    static const char *xyzw[] = {"x", "y", "z", "w"};
    struct timespec ts;
    clock_gettime(CLOCK_REALTIME, &ts);
    const double q[4] = {0.0, 0.0, 0.0, 1.0};
    const double w[3] = {0.5, -0.25, 0.001 * (double)i};
    const double a[3] = {0.0, 0.0, 9.81};
    if (array_form) { msgpack_pack_array(pk, 8); pack_str(pk, name); }
    else if (form == FORM_CVRA) { msgpack_pack_array(pk, 2); pack_str(pk, name); msgpack_pack_map(pk, 7); }
    else { pack_str(pk, name); msgpack_pack_map(pk, 7); }
    pack_key(pk, "header", array_form);
    if (array_form) msgpack_pack_array(pk, 3); else msgpack_pack_map(pk, 3);
    pack_key(pk, "seq", array_form);
    msgpack_pack_uint32(pk, (uint32_t)i);
    pack_key(pk, "stamp", array_form);
    msgpack_pack_array(pk, 2);
    msgpack_pack_uint32(pk, (uint32_t)ts.tv_sec);
    msgpack_pack_uint32(pk, (uint32_t)ts.tv_nsec);
    pack_key(pk, "frame_id", array_form);
    pack_str(pk, "imu_link");
    pack_key(pk, "orientation", array_form);
    pack_vector(pk, array_form, xyzw, q, 4);
    pack_key(pk, "orientation_covariance", array_form);
    pack_covariance(pk, 0.01);
    pack_key(pk, "angular_velocity", array_form);
    pack_vector(pk, array_form, xyz, w, 3);
    pack_key(pk, "angular_velocity_covariance", array_form);
    pack_covariance(pk, 0.02);
    pack_key(pk, "linear_acceleration", array_form);
    pack_vector(pk, array_form, xyz, a, 3);
    pack_key(pk, "linear_acceleration_covariance", array_form);
    pack_covariance(pk, 0.04);
}

/* ------------------------------------------------------------------ sockets */

static int make_socket(int type, const char *address, int port) {
    int fd = socket(AF_INET, type, 0);
    int one = 1;
    struct sockaddr_in sa = {0};
    if (fd < 0) { perror("socket"); exit(2); }
    setsockopt(fd, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sa.sin_family = AF_INET;
    sa.sin_port = htons((uint16_t)port);
    if (inet_pton(AF_INET, address, &sa.sin_addr) != 1) { fprintf(stderr, "bad address %s\n", address); exit(2); }
    if (bind(fd, (struct sockaddr *)&sa, sizeof sa) < 0) {
        fprintf(stderr, "cannot bind %s:%d: %s\n", address, port, strerror(errno));
        exit(2);
    }
    return fd;
}

static struct sockaddr_in peer_addr(const char *address, int port) {
    struct sockaddr_in sa = {0};
    sa.sin_family = AF_INET;
    sa.sin_port = htons((uint16_t)port);
    inet_pton(AF_INET, address, &sa.sin_addr);
    return sa;
}

/* Read until END (or until EOF/limit when until_end is 0), at most timeout seconds; returns bytes or -1. */
static long read_until(int fd, unsigned char *buf, size_t cap, double timeout, int until_end) {
    size_t n = 0;
    double deadline = now_mono() + timeout;
    for (;;) {
        double left = deadline - now_mono();
        struct pollfd p = {fd, POLLIN, 0};
        if (left <= 0 || n >= cap) return -1;
        if (poll(&p, 1, (int)(left * 1000) + 1) <= 0) continue;
        ssize_t got = recv(fd, buf + n, cap - n, 0);
        if (got <= 0) return until_end ? -1 : (long)n;
        for (ssize_t k = 0; k < got; k++) {
            if (until_end && buf[n + k] == END) return (long)(n + k);
        }
        n += (size_t)got;
    }
}

static void receive_datagram(int udp, int form) {
    unsigned char buf[65536];
    char control[64];
    struct sockaddr_in from;
    struct iovec iov = {buf, sizeof buf};
    struct msghdr mh = {0};
    mh.msg_name = &from; mh.msg_namelen = sizeof from;
    mh.msg_iov = &iov; mh.msg_iovlen = 1;
    mh.msg_control = control; mh.msg_controllen = sizeof control;
    ssize_t n = recvmsg(udp, &mh, MSG_DONTWAIT);
    if (n < 0) return;
    int tos = -1;
    for (struct cmsghdr *c = CMSG_FIRSTHDR(&mh); c; c = CMSG_NXTHDR(&mh, c))
        if (c->cmsg_level == IPPROTO_IP && c->cmsg_type == IP_TOS) tos = *(unsigned char *)CMSG_DATA(c);
    msgpack_unpacked first, second;
    msgpack_unpacked_init(&first);
    msgpack_unpacked_init(&second);
    size_t off = 0;
    printf("{\"event\": \"recv\", \"bytes\": %zd, \"tos\": %d, ", n, tos);
    int ok = msgpack_unpack_next(&first, (const char *)buf, (size_t)n, &off) == MSGPACK_UNPACK_SUCCESS;
    if (ok && form == FORM_CVRA && first.data.type == MSGPACK_OBJECT_ARRAY && first.data.via.array.size == 2 &&
        first.data.via.array.ptr[0].type == MSGPACK_OBJECT_STR) {  /* as CVRA's message_process: argc == 2 */
        printf("\"name\": ");
        json_string(first.data.via.array.ptr[0].via.str.ptr, first.data.via.array.ptr[0].via.str.size);
        printf(", \"fields\": ");
        json_object(&first.data.via.array.ptr[1]);
    } else if (ok && form != FORM_CVRA && first.data.type == MSGPACK_OBJECT_STR &&
               msgpack_unpack_next(&second, (const char *)buf, (size_t)n, &off) == MSGPACK_UNPACK_SUCCESS) {
        printf("\"name\": ");
        json_string(first.data.via.str.ptr, first.data.via.str.size);
        printf(", \"fields\": ");
        json_object(&second.data);
    } else {
        printf("\"name\": null, \"fields\": null");
    }
    printf("}\n");
    fflush(stdout);
    msgpack_unpacked_destroy(&first);
    msgpack_unpacked_destroy(&second);
}

static long served = 0;

static void serve_one(int listener, const char *service_name, const char *hang_name, int form) {
    unsigned char buf[MAX_FRAME];
    int conn = accept(listener, NULL, NULL);
    if (conn < 0) return;
    long n = read_until(conn, buf, sizeof buf, 2.0, 1);
    long len = n < 0 ? -1 : slip_unframe(buf, (size_t)n);
    msgpack_unpacked req, req2;
    msgpack_unpacked_init(&req);
    msgpack_unpacked_init(&req2);
    size_t off = 0;
    int ok = len >= 0 && msgpack_unpack_next(&req, (const char *)buf, (size_t)len, &off) == MSGPACK_UNPACK_SUCCESS;
    if (form == FORM_CVRA)  /* as CVRA's service_call_process: an array of exactly 2, a name first */
        ok = ok && req.data.type == MSGPACK_OBJECT_ARRAY && req.data.via.array.size == 2 &&
             req.data.via.array.ptr[0].type == MSGPACK_OBJECT_STR;
    else  /* the README's: the name, then the parameters' map, two objects */
        ok = ok && req.data.type == MSGPACK_OBJECT_STR &&
             msgpack_unpack_next(&req2, (const char *)buf, (size_t)len, &off) == MSGPACK_UNPACK_SUCCESS &&
             req2.data.type == MSGPACK_OBJECT_MAP;
    if (!ok) {
        printf("{\"event\": \"bad_frame\", \"bytes\": %ld}\n", n);
        fflush(stdout);
        msgpack_unpacked_destroy(&req);
        msgpack_unpacked_destroy(&req2);
        close(conn);
        return;
    }
    const msgpack_object_str *name = form == FORM_CVRA ? &req.data.via.array.ptr[0].via.str : &req.data.via.str;
    int ours = name->size == strlen(service_name) && memcmp(name->ptr, service_name, name->size) == 0;
    int hang = *hang_name && name->size == strlen(hang_name) && memcmp(name->ptr, hang_name, name->size) == 0;
    printf("{\"event\": \"served\", \"name\": ");
    json_string(name->ptr, name->size);
    printf(", \"params\": ");
    json_object(form == FORM_CVRA ? &req.data.via.array.ptr[1] : &req2.data);  /* what follows the name */
    printf(", \"known\": %s}\n", ours ? "true" : "false");
    fflush(stdout);
    if (hang) read_until(conn, buf, sizeof buf, 3.0, 0);  /* a board that never answers: wait for the caller to give up */
    if (ours) {
        char message[64];
        msgpack_sbuffer sb;
        msgpack_packer pk;
        snprintf(message, sizeof message, "reset done (%ld)", ++served);
        msgpack_sbuffer_init(&sb);
        msgpack_packer_init(&pk, &sb, msgpack_sbuffer_write);
        msgpack_pack_map(&pk, 2);
        pack_str(&pk, "success");
        msgpack_pack_true(&pk);
        pack_str(&pk, "message");
        pack_str(&pk, message);
        send(conn, sb.data, sb.size, MSG_NOSIGNAL);
        msgpack_sbuffer_destroy(&sb);
    }
    msgpack_unpacked_destroy(&req);
    msgpack_unpacked_destroy(&req2);
    close(conn);
}

static void pack_arg(msgpack_packer *pk, const char *s) {
    char *end;
    if (strcmp(s, "true") == 0) { msgpack_pack_true(pk); return; }
    if (strcmp(s, "false") == 0) { msgpack_pack_false(pk); return; }
    long long v = strtoll(s, &end, 10);
    if (*s && *end == 0) { msgpack_pack_int64(pk, v); return; }
    double d = strtod(s, &end);
    if (*s && *end == 0) { msgpack_pack_double(pk, d); return; }
    pack_str(pk, s);
}

static void call_bridge(const struct options *o) {
    unsigned char frame[2 * 4096 + 16], answer[MAX_FRAME];
    msgpack_sbuffer sb;
    msgpack_packer pk;
    msgpack_sbuffer_init(&sb);
    msgpack_packer_init(&pk, &sb, msgpack_sbuffer_write);
    if (o->form == FORM_CVRA) {  /* encode_call(name, [args...]), or encode_call(name) -> [name, nil] */
        msgpack_pack_array(&pk, 2);
        pack_str(&pk, o->call_name);
        if (o->n_call_args) msgpack_pack_array(&pk, o->n_call_args); else msgpack_pack_nil(&pk);
    } else {  /* the README's: the name, then a map of --call-key: --call-arg */
        pack_str(&pk, o->call_name);
        msgpack_pack_map(&pk, o->n_call_args);
    }
    for (int i = 0; i < o->n_call_args; i++) {
        if (o->form != FORM_CVRA) pack_str(&pk, i < o->n_call_keys ? o->call_keys[i] : "data");
        pack_arg(&pk, o->call_args[i]);
    }
    size_t flen = slip_frame((const unsigned char *)sb.data, sb.size, frame);
    msgpack_sbuffer_destroy(&sb);
    int fd = make_socket(SOCK_STREAM, o->address, 0);
    struct sockaddr_in to = peer_addr(o->bridge, o->bridge_service_port);
    double t0 = now_mono();
    if (connect(fd, (struct sockaddr *)&to, sizeof to) < 0 || send(fd, frame, flen, MSG_NOSIGNAL) != (ssize_t)flen) {
        printf("{\"event\": \"call_result\", \"name\": \"%s\", \"error\": \"%s\"}\n", o->call_name, strerror(errno));
        fflush(stdout);
        close(fd);
        return;
    }
    long n = read_until(fd, answer, sizeof answer, 5.0, 0);
    close(fd);
    msgpack_unpacked res;
    msgpack_unpacked_init(&res);
    size_t off = 0;
    printf("{\"event\": \"call_result\", \"name\": \"%s\", \"seconds\": %.4f, \"response\": ", o->call_name, now_mono() - t0);
    if (n > 0 && msgpack_unpack_next(&res, (const char *)answer, (size_t)n, &off) == MSGPACK_UNPACK_SUCCESS)
        json_object(&res.data);
    else
        printf("null");
    printf("}\n");
    fflush(stdout);
    msgpack_unpacked_destroy(&res);
}

/* ------------------------------------------------------------------ main */

static void usage(void) {
    fprintf(stderr,
            "mcu_standin [--address A] [--topic-port P] [--service-port P] [--bridge A] [--bridge-topic-port P]\n"
            "            [--bridge-service-port P] [--rate HZ] [--count N] [--stream-name NAME] [--form cvra|readme] [--array-form]\n"
            "            [--pause-after N --pause S] [--service-name NAME] [--hang-name NAME] [--call NAME [--call-arg V]...\n"
            "            [--call-key K]... --call-after S] [--duration S] [--linger S]\n");
    exit(2);
}

int main(int argc, char **argv) {
    struct options o = {"127.0.0.2", "127.0.0.1", "imu", "reset", "", NULL, {0}, {0}, 0, 0,
                        20000, 20001, 20000, 20001, 100.0, 60.0, 0.0, 0.5, 1.0, 0, 0, FORM_CVRA, 0};
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (strcmp(a, "--array-form") == 0) { o.array_form = 1; continue; }
        if (!v) usage();
        i++;
        if (strcmp(a, "--address") == 0) o.address = v;
        else if (strcmp(a, "--topic-port") == 0) o.topic_port = atoi(v);
        else if (strcmp(a, "--service-port") == 0) o.service_port = atoi(v);
        else if (strcmp(a, "--bridge") == 0) o.bridge = v;
        else if (strcmp(a, "--bridge-topic-port") == 0) o.bridge_topic_port = atoi(v);
        else if (strcmp(a, "--bridge-service-port") == 0) o.bridge_service_port = atoi(v);
        else if (strcmp(a, "--rate") == 0) o.rate = atof(v);
        else if (strcmp(a, "--count") == 0) o.count = atol(v);
        else if (strcmp(a, "--stream-name") == 0) o.stream_name = v;
        else if (strcmp(a, "--pause-after") == 0) o.pause_after = atol(v);
        else if (strcmp(a, "--pause") == 0) o.pause = atof(v);
        else if (strcmp(a, "--service-name") == 0) o.service_name = v;
        else if (strcmp(a, "--hang-name") == 0) o.hang_name = v;
        else if (strcmp(a, "--call") == 0) o.call_name = v;
        else if (strcmp(a, "--call-arg") == 0 && o.n_call_args < MAX_ARGS) o.call_args[o.n_call_args++] = v;
        else if (strcmp(a, "--call-key") == 0 && o.n_call_keys < MAX_ARGS) o.call_keys[o.n_call_keys++] = v;
        else if (strcmp(a, "--call-after") == 0) o.call_after = atof(v);
        else if (strcmp(a, "--duration") == 0) o.duration = atof(v);
        else if (strcmp(a, "--linger") == 0) o.linger = atof(v);
        else if (strcmp(a, "--form") == 0) {
            if (strcmp(v, "cvra") == 0) o.form = FORM_CVRA;
            else if (strcmp(v, "readme") == 0) o.form = FORM_README;
            else usage();
        }
        else usage();
    }
    signal(SIGINT, on_signal);
    signal(SIGTERM, on_signal);
    signal(SIGPIPE, SIG_IGN);

    int one = 1;
    int udp = make_socket(SOCK_DGRAM, o.address, o.topic_port);
    setsockopt(udp, IPPROTO_IP, IP_RECVTOS, &one, sizeof one);
    int listener = make_socket(SOCK_STREAM, o.address, o.service_port);
    listen(listener, 16);
    struct sockaddr_in bridge = peer_addr(o.bridge, o.bridge_topic_port);
    printf("{\"event\": \"ready\", \"address\": \"%s\", \"topic_port\": %d, \"service_port\": %d}\n",
           o.address, o.topic_port, o.service_port);
    fflush(stdout);

    msgpack_sbuffer sb;
    msgpack_packer pk;
    msgpack_sbuffer_init(&sb);
    msgpack_packer_init(&pk, &sb, msgpack_sbuffer_write);
    double start = now_mono(), period = o.rate > 0 ? 1.0 / o.rate : 0.0;
    double next_send = start, call_at = o.call_name ? start + o.call_after : -1.0;
    double end = start + o.duration, finished_at = -1.0, resume_at = -1.0;
    long sent = 0;
    while (!stop_requested) {
        double t = now_mono();
        if (t >= end || (finished_at > 0 && t >= finished_at + o.linger)) break;
        if (call_at > 0 && t >= call_at) { call_at = -1.0; call_bridge(&o); continue; }
        if (resume_at > 0 && t >= resume_at) {
            resume_at = -1.0;
            next_send = t;
            printf("{\"event\": \"resumed\", \"sent\": %ld}\n", sent);
            fflush(stdout);
        }
        int streaming = period > 0 && resume_at < 0 && finished_at < 0;
        if (streaming && t >= next_send) {
            msgpack_sbuffer_clear(&sb);
            pack_imu(&pk, o.stream_name, sent, o.form, o.array_form);
            sendto(udp, sb.data, sb.size, 0, (struct sockaddr *)&bridge, sizeof bridge);
            sent++;
            next_send += period;
            if (next_send < t - 0.5) next_send = t;  /* do not burst after a stall */
            if (o.count > 0 && sent >= o.count) {
                finished_at = t;
                printf("{\"event\": \"sent\", \"sent\": %ld}\n", sent);
                fflush(stdout);
            } else if (o.pause_after > 0 && sent == o.pause_after && o.pause > 0) {
                resume_at = t + o.pause;
                printf("{\"event\": \"paused\", \"sent\": %ld, \"seconds\": %.3f}\n", sent, o.pause);
                fflush(stdout);
            }
            continue;
        }
        double wake = end;
        if (streaming && next_send < wake) wake = next_send;
        if (call_at > 0 && call_at < wake) wake = call_at;
        if (resume_at > 0 && resume_at < wake) wake = resume_at;
        if (finished_at > 0 && finished_at + o.linger < wake) wake = finished_at + o.linger;
        int ms = (int)((wake - t) * 1000.0);
        if (ms < 0) ms = 0;
        if (ms > 100) ms = 100;
        struct pollfd fds[2] = {{udp, POLLIN, 0}, {listener, POLLIN, 0}};
        if (poll(fds, 2, ms) > 0) {
            if (fds[0].revents & POLLIN) receive_datagram(udp, o.form);
            if (fds[1].revents & POLLIN) serve_one(listener, o.service_name, o.hang_name, o.form);
        }
    }
    msgpack_sbuffer_destroy(&sb);
    printf("{\"event\": \"done\", \"sent\": %ld, \"served\": %ld}\n", sent, served);
    fflush(stdout);
    close(udp);
    close(listener);
    return 0;
}
