/* A Cyclone DDS participant that joins a tending fleet as a ROS 2 peer (issue 38).
 *
 * Security is configured the way rmw_cyclonedds configures it from an SROS2 enclave:
 * participant QoS properties naming the enclave's six files (identity_ca.cert.pem,
 * cert.pem, key.pem, permissions_ca.cert.pem, governance.p7s, permissions.p7s) and
 * Cyclone's builtin plugins. Without --enclave the participant is an ordinary,
 * unauthenticated one.
 *
 *   cyclone_peer --domain D [--enclave DIR] [--read rt/robot_0/pose] [--read2 TOPIC]
 *                [--write rt/robot_0/cmd_vel --vx 0.1] [--seconds S] [--until N]
 *
 * It prints "guid=<its GUID prefix, 24 hex digits>" first, reads
 * geometry_msgs/PoseStamped samples from --read (and --read2, counted apart: a control),
 * publishes a geometry_msgs/Twist every 50 ms on --write, and prints one line per second
 * and a last line "result read=N read2=N2 big=B wrote=M last_x=X matched_pub=P
 * matched_sub=Q" (B: poses read whose header.frame_id has 1024 characters or more, i.e.
 * samples the writer had to send in fragments).
 * It stops after --seconds, or once it has read --until samples and seen its writer
 * matched for a second. Exit 0; 2 when the participant (or an entity) cannot be
 * created, with Cyclone's reason on stderr.
 *
 * QoS: reliable, volatile, keep-last 10 (msgs::Profile::RobotStream, the fleet's
 * pose and cmd_vel profile). Types: tests/cyclone/ros_msgs.idl (idlc).
 */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dds/dds.h"
#include "ros_msgs.h"

#ifndef PLUGIN_DIR
#define PLUGIN_DIR ""
#endif

static void plugin(dds_qos_t *q, const char *kind, const char *lib, const char *init,
                   const char *fini)
{
  char name[128], path[512];
  snprintf(path, sizeof path, "%s%s%s", PLUGIN_DIR, PLUGIN_DIR[0] ? "/lib" : "", lib);
  if (PLUGIN_DIR[0])
    strncat(path, ".so", sizeof path - strlen(path) - 1);
  snprintf(name, sizeof name, "dds.sec.%s.library.path", kind);
  dds_qset_prop(q, name, path);
  snprintf(name, sizeof name, "dds.sec.%s.library.init", kind);
  dds_qset_prop(q, name, init);
  snprintf(name, sizeof name, "dds.sec.%s.library.finalize", kind);
  dds_qset_prop(q, name, fini);
}

static void file_prop(dds_qos_t *q, const char *prop, const char *dir, const char *file)
{
  char uri[1024];
  snprintf(uri, sizeof uri, "file:%s/%s", dir, file);
  dds_qset_prop(q, prop, uri);
}

static int fail(const char *what, dds_return_t rc)
{
  fprintf(stderr, "cyclone_peer: %s: %s\n", what, dds_strretcode(rc < 0 ? -rc : rc));
  printf("result refused=%s\n", what);
  fflush(stdout);
  return 2;
}

int main(int argc, char **argv)
{
  int domain = 0, until = -1;
  double seconds = 20.0, vx = 0.1;
  const char *enclave = NULL, *rtopic = NULL, *rtopic2 = NULL, *wtopic = NULL;
  for (int i = 1; i < argc; i++)
  {
    const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
    if (!v)
    {
      fprintf(stderr, "cyclone_peer: %s needs a value\n", a);
      return 64;
    }
    if (!strcmp(a, "--domain")) domain = atoi(v);
    else if (!strcmp(a, "--enclave")) enclave = v;
    else if (!strcmp(a, "--read")) rtopic = v;
    else if (!strcmp(a, "--read2")) rtopic2 = v;
    else if (!strcmp(a, "--write")) wtopic = v;
    else if (!strcmp(a, "--seconds")) seconds = atof(v);
    else if (!strcmp(a, "--until")) until = atoi(v);
    else if (!strcmp(a, "--vx")) vx = atof(v);
    else
    {
      fprintf(stderr, "cyclone_peer: unknown option %s\n", a);
      return 64;
    }
    i++;
  }

  dds_qos_t *pq = dds_create_qos();
  if (enclave)
  {
    plugin(pq, "auth", "dds_security_auth", "init_authentication", "finalize_authentication");
    plugin(pq, "crypto", "dds_security_crypto", "init_crypto", "finalize_crypto");
    plugin(pq, "access", "dds_security_ac", "init_access_control", "finalize_access_control");
    file_prop(pq, "dds.sec.auth.identity_ca", enclave, "identity_ca.cert.pem");
    file_prop(pq, "dds.sec.auth.identity_certificate", enclave, "cert.pem");
    file_prop(pq, "dds.sec.auth.private_key", enclave, "key.pem");
    file_prop(pq, "dds.sec.access.permissions_ca", enclave, "permissions_ca.cert.pem");
    file_prop(pq, "dds.sec.access.governance", enclave, "governance.p7s");
    file_prop(pq, "dds.sec.access.permissions", enclave, "permissions.p7s");
  }
  dds_entity_t pp = dds_create_participant((dds_domainid_t)domain, pq, NULL);
  dds_delete_qos(pq);
  if (pp < 0)
    return fail("participant", pp);
  dds_guid_t guid;
  if (dds_get_guid(pp, &guid) == DDS_RETCODE_OK)
  {
    printf("guid=");
    for (int i = 0; i < 12; i++)
      printf("%02x", guid.v[i]);
    printf("\n");
  }

  dds_qos_t *q = dds_create_qos();
  dds_qset_reliability(q, DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
  dds_qset_durability(q, DDS_DURABILITY_VOLATILE);
  dds_qset_history(q, DDS_HISTORY_KEEP_LAST, 10);

  dds_entity_t rd = 0, rd2 = 0, wr = 0;
  const char *rtopics[2] = {rtopic, rtopic2};
  dds_entity_t *rds[2] = {&rd, &rd2};
  for (int k = 0; k < 2; k++)
  {
    if (!rtopics[k])
      continue;
    dds_entity_t t = dds_create_topic(pp, &geometry_msgs_msg_dds__PoseStamped__desc, rtopics[k], NULL, NULL);
    if (t < 0)
      return fail("topic", t);
    *rds[k] = dds_create_reader(pp, t, q, NULL);
    if (*rds[k] < 0)
      return fail("reader", *rds[k]);
  }
  if (wtopic)
  {
    dds_entity_t t = dds_create_topic(pp, &geometry_msgs_msg_dds__Twist__desc, wtopic, NULL, NULL);
    if (t < 0)
      return fail("topic", t);
    wr = dds_create_writer(pp, t, q, NULL);
    if (wr < 0)
      return fail("writer", wr);
  }
  dds_delete_qos(q);
  printf("participant up (%s)\n", enclave ? enclave : "no security");
  fflush(stdout);

  long nread = 0, nread2 = 0, nbig = 0, nwrote = 0;
  double last_x = 0.0;
  uint32_t matched_pub = 0, matched_sub = 0;
  int matched_ticks = 0;
  const int ticks = (int)(seconds * 20.0);
  for (int tick = 0; tick < ticks; tick++)
  {
    if (wr)
    {
      geometry_msgs_msg_dds__Twist_ cmd;
      memset(&cmd, 0, sizeof cmd);
      cmd.linear.x = vx;
      if (dds_write(wr, &cmd) == DDS_RETCODE_OK)
        nwrote++;
      dds_publication_matched_status_t st;
      if (dds_get_publication_matched_status(wr, &st) == 0)
        matched_pub = st.current_count;
    }
    if (rd)
    {
      void *samples[16] = {NULL};
      dds_sample_info_t infos[16];
      int n = dds_take(rd, samples, infos, 16, 16);
      for (int i = 0; i < n; i++)
        if (infos[i].valid_data)
        {
          const geometry_msgs_msg_dds__PoseStamped_ *p = samples[i];
          nread++;
          last_x = p->pose.position.x;
          if (p->header.frame_id && strlen(p->header.frame_id) >= 1024)
            nbig++;
        }
      if (n > 0)
        dds_return_loan(rd, samples, n);
      dds_subscription_matched_status_t st;
      if (dds_get_subscription_matched_status(rd, &st) == 0)
        matched_sub = st.current_count;
    }
    if (rd2)
    {
      void *samples[16] = {NULL};
      dds_sample_info_t infos[16];
      int n = dds_take(rd2, samples, infos, 16, 16);
      for (int i = 0; i < n; i++)
        nread2 += infos[i].valid_data ? 1 : 0;
      if (n > 0)
        dds_return_loan(rd2, samples, n);
    }
    if (tick % 20 == 19)
    {
      printf("t=%ds read=%ld wrote=%ld matched_pub=%u matched_sub=%u\n", (tick + 1) / 20, nread,
             nwrote, matched_pub, matched_sub);
      fflush(stdout);
    }
    matched_ticks = (!wr || matched_pub > 0) ? matched_ticks + 1 : 0;
    if (until >= 0 && nread >= until && matched_ticks >= 20)
      break;
    dds_sleepfor(DDS_MSECS(50));
  }
  printf("result read=%ld read2=%ld big=%ld wrote=%ld last_x=%g matched_pub=%u matched_sub=%u\n",
         nread, nread2, nbig, nwrote, last_x, matched_pub, matched_sub);
  fflush(stdout);
  dds_delete(pp);
  return 0;
}
